"""The shipped FPN quantized to int8 (``--precision int8``): what making it costs once, and how
fast and how close to float32 it runs on ONNX Runtime.

    .venv/bin/python benchmarks/int8_speed.py [CITY] [--repeats 5] [--windows 4]

Exports the float32 FPN, quantizes it as the engine does on first use
(``csboundary.models.onnx_quantization.quantize_fpn``: seconds and the process's peak memory,
which the quantizer sets), then times float32 and int8 at both of ONNX Runtime's graph
optimisation levels on the first windows of CITY (default: the 16-patch seed-7 test city), in
turn, the median of ``--repeats`` runs each after one warm-up, this machine's threads. Prints the
mean and largest probability difference to float32 over those windows and the share of pixels
that moved by more than 0.1.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from csboundary.data.grid import PatchGrid
from csboundary.data.raster import Mosaic
from csboundary.models.maps import unit_bands
from csboundary.models.onnx_engine import export_fpn
from csboundary.models.onnx_quantization import quantize_fpn
from csboundary.models.onnx_session import LEVELS, open_session
from csboundary.pipeline.outputs.run_summary import peak_rss_mb
from csboundary.pipeline.prediction.patch import PatchPredictor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city", nargs="?", type=Path, default=Path("data/cities/test-s7-2x2-2000"))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--windows", type=int, default=4)
    args = parser.parse_args()
    with Mosaic.open(args.city / "tiles") as mosaic:
        windows = [
            unit_bands(mosaic.read(p.expanded).data[None]) for p in list(PatchGrid.for_mosaic(mosaic))[: args.windows]
        ]
    float_model = export_fpn(PatchPredictor.load(None, torch.device("cpu")).fpn)
    before = peak_rss_mb()
    start = time.perf_counter()
    int8_model = quantize_fpn(float_model)
    print(
        f"quantized in {time.perf_counter() - start:.1f} s; peak memory {peak_rss_mb():.0f} MB "
        f"(before quantizing {before:.0f} MB); "
        f"{len(float_model) / 2**20:.1f} MB -> {len(int8_model) / 2**20:.1f} MB"
    )
    threads = torch.get_num_threads()
    sessions = {
        (name, level): open_session(model, threads, level, name)
        for name, model in (("float32", float_model), ("int8", int8_model))
        for level in LEVELS
    }
    probs = {key: [] for key in sessions}
    times = {key: [] for key in sessions}
    for key, session in sessions.items():
        session.run(None, {"image": windows[0]})
        for window in windows:
            probs[key].append(1 / (1 + np.exp(-session.run(None, {"image": window})[0])))
    for _ in range(args.repeats):
        for key, session in sessions.items():  # in turn: a change in the machine's load falls on every variant
            start = time.perf_counter()
            session.run(None, {"image": windows[0]})
            times[key].append(time.perf_counter() - start)
    reference = probs["float32", "extended"]
    for (name, level), found in probs.items():
        diff = np.concatenate([np.abs(a - b).ravel() for a, b in zip(found, reference)])
        print(
            f"{name:8s} {level:9s} {statistics.median(times[name, level]):.3f} s per window, {threads} threads; "
            f"probability difference to float32: mean {diff.mean():.5f}, largest {diff.max():.3f}, "
            f"over 0.1 {np.mean(diff > 0.1):.5f}"
        )


if __name__ == "__main__":
    main()
