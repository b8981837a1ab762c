"""The run store's float16 conversions, alone and beside a busy core (why they run in pieces).

    .venv/bin/python benchmarks/float16_speed.py

Times, for one (3, 1100, 1100) patch: storing it as float16 and adding a (3, 1050, 1050) float16
view into a float32 window sum, each by NumPy, by one PyTorch call (which wakes PyTorch's thread
pool) and by :mod:`csboundary.pipeline.prediction.float16` (pieces PyTorch runs on the calling thread).
First with the machine idle, then with a thread multiplying matrices beside it, as the FPN does
in the city pipeline. Prints the median and the largest of 25 runs, in milliseconds.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import torch

from csboundary.pipeline.prediction.float16 import add_float32, to_float16


def timed(fn, runs: int = 25) -> str:
    fn()
    seconds = []
    for _ in range(runs):
        start = time.perf_counter()
        fn()
        seconds.append(time.perf_counter() - start)
    return f"{np.median(seconds) * 1e3:6.2f} ms (largest {max(seconds) * 1e3:5.1f})"


def main() -> None:
    rng = np.random.default_rng(0)
    maps = rng.random((3, 1100, 1100), dtype=np.float32)
    stored = maps.astype(np.float16)
    total = np.zeros_like(maps)
    view, part = total[:, 50:, :1050], stored[:, :1050, 50:]
    cases = {
        "store, NumPy": lambda: maps.astype(np.float16),
        "store, one PyTorch call": lambda: torch.from_numpy(maps).to(torch.float16),
        "store, pieces (shipped)": lambda: to_float16(maps),
        "add, NumPy": lambda: np.add(view, part, out=view),
        "add, one PyTorch call": lambda: torch.from_numpy(view).add_(torch.from_numpy(part)),
        "add, pieces (shipped)": lambda: add_float32(view, part),
    }
    busy = threading.Event()

    def matrix_work():
        a = rng.random((1500, 1500))
        while not busy.is_set():
            a @ a  # NumPy's BLAS leaves the GIL: a core kept busy, as by the FPN

    for label in ("idle", "a busy thread beside it"):
        worker = None
        if label != "idle":
            worker = threading.Thread(target=matrix_work, daemon=True)
            worker.start()
        print(f"{label} (PyTorch threads: {torch.get_num_threads()}):")
        for name, fn in cases.items():
            print(f"  {name:26s} {timed(fn)}")
        if worker is not None:
            busy.set()
            worker.join()


if __name__ == "__main__":
    main()
