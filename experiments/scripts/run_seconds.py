"""Experiment: where a city run's wall time goes beyond its FPN, with every network on one thread.

    .venv/bin/python experiments/scripts/run_seconds.py CITY [float32|int8]

Runs ``run_prediction`` on CITY twice with the onnx engine (the first warms the sessions up) and
prints the second run's wall time and its summary's seconds per stage (each on the thread that
ran it: the FPN on its own thread, the city graph's steps and the outputs after the last window).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import torch


def main() -> None:
    torch.set_num_threads(1)  # ONNX Runtime's sessions take their thread count from it: the FPN on one core
    from csboundary.data.raster import Mosaic
    from csboundary.pipeline.patch import PatchPredictor
    from csboundary.pipeline.run import run_prediction

    city, precision = Path(sys.argv[1]), (sys.argv[2] if len(sys.argv) > 2 else "int8")
    predictor = PatchPredictor.load(None, torch.device("cpu"))
    predictor.use_precision(precision)
    predictor.use_engine("onnx", None)
    with Mosaic.open(city / "tiles") as mosaic, tempfile.TemporaryDirectory() as tmp:
        run_prediction(mosaic, predictor, Path(tmp) / "warm-up", progress=False)
        start = time.perf_counter()
        _, summary = run_prediction(mosaic, predictor, Path(tmp) / "run", progress=False)
        print(json.dumps({"wall_s": round(time.perf_counter() - start, 3), "patches": summary["patches"], "seconds": summary["seconds"],
                          "core_seconds_per_patch": summary["core_seconds_per_patch"]}, indent=1))


if __name__ == "__main__":
    main()
