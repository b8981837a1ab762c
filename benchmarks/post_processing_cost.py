"""Core seconds per patch of everything in a city run but the FPN, by thread (issue 15).

    .venv/bin/python benchmarks/post_processing_cost.py [CITY] [--engine onnx|torch]

The FPN's maps of every patch are computed first; then ``run_prediction`` runs on the city with
a model that hands those maps back instead of running the FPN, so what it costs is the rest of
the pipeline: reading, storing, map stitching, vertices, AfANet, graph stitching and the output
files. A second run is measured (the first opens the AfANet session and warms the caches).
Prints its wall and core seconds per patch and each thread's core seconds per patch (read from
``/proc/self/task`` every 20 ms; threads the pipeline names, and the native pools of ONNX
Runtime / PyTorch together). On two cores, a ratio of at most 1.2 between the whole run and
the FPN alone needs this below about 0.4 x the FPN's own core seconds minus what the FPN leaves
idle (``benchmarks/engine_speed.py`` prints both).
"""

from __future__ import annotations

import argparse
import collections
import os
import tempfile
import threading
import time
from pathlib import Path

import torch

from csboundary.data.grid import PatchGrid
from csboundary.data.nodata import fill_nodata
from csboundary.data.raster import Mosaic
from csboundary.pipeline.jobs.prediction_run import run_prediction
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.patch import PatchPredictor


class StoredMaps:
    """The predictor, with the FPN replaced by maps computed beforehand."""

    def __init__(self, predictor: PatchPredictor, maps: dict):
        self.predictor, self.maps = predictor, maps

    def __getattr__(self, name):
        return getattr(self.predictor, name)

    def patch_maps(self, patches, images):
        return [self.maps[p.index].copy() for p in patches]


class ThreadClock:
    """Core seconds of each thread of this process, sampled until stopped."""

    def __init__(self):
        self.tick = os.sysconf("SC_CLK_TCK")
        self.start = self._sample()
        self.last: dict[str, tuple[str, float]] = {}
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, name="clock", daemon=True)
        self.thread.start()

    def _cpu(self, tid: str) -> float:
        fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / self.tick

    def _sample(self) -> dict[str, float]:
        out = {}
        for tid in os.listdir("/proc/self/task"):
            try:
                out[tid] = self._cpu(tid)
            except OSError:  # the thread ended meanwhile
                pass
        return out

    def _run(self) -> None:
        while not self.done.is_set():
            names = {str(t.native_id): t.name.rsplit("_", 1)[0] for t in threading.enumerate()}
            for tid, seconds in self._sample().items():
                known = self.last.get(tid, ("native pools",))[0]
                self.last[tid] = (names.get(tid, known), seconds)
            time.sleep(0.02)

    def stop(self) -> dict[str, float]:
        self.done.set()
        self.thread.join()
        totals: dict[str, float] = collections.Counter()
        for tid, (name, seconds) in self.last.items():
            if name != "clock":
                totals[name] += seconds - self.start.get(tid, 0.0)
        return dict(totals)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city", nargs="?", type=Path, default=Path("data/cities/test-s7-2x2-2000"))
    parser.add_argument("--engine", default="onnx", choices=("onnx", "torch"))
    args = parser.parse_args()
    predictor = PatchPredictor.load(None, torch.device("cpu"))
    predictor.use_engine(args.engine, None)
    with Mosaic.open(args.city / "tiles") as mosaic, tempfile.TemporaryDirectory() as tmp:
        maps = {}
        for patch in PatchGrid.for_mosaic(mosaic):
            read = mosaic.read(patch.expanded)
            maps[patch.index] = predictor.patch_maps([patch], [fill_nodata(read.data, read.valid)])[0]
        model = StoredMaps(predictor, maps)
        run_prediction(mosaic, model, Path(tmp) / "warm", PredictionOptions(progress=False), settings={})
        clock = ThreadClock()
        start, cores = time.perf_counter(), time.process_time()
        _, summary = run_prediction(mosaic, model, Path(tmp) / "run", PredictionOptions(progress=False), settings={})
        wall, cores = time.perf_counter() - start, time.process_time() - cores
        threads = clock.stop()
    n = summary["patches"]
    print(
        f"{args.engine}, {n} patches, without the FPN: wall {wall / n:.3f} s/patch, core {cores / n:.3f} s/patch "
        f"(outputs {summary['seconds']['outputs']:.2f} s)"
    )
    print(
        "  by thread, core s/patch: "
        + ", ".join(f"{name} {seconds / n:.3f}" for name, seconds in sorted(threads.items(), key=lambda kv: -kv[1]))
    )


if __name__ == "__main__":
    main()
