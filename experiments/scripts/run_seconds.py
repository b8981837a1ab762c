"""Experiment: where a city run's wall time goes beyond its FPN.

    .venv/bin/python experiments/scripts/run_seconds.py CITY [auto|float32|int8] [--one-thread]

Runs ``run_prediction`` on CITY twice with the onnx engine (the first warms the sessions up) and
prints the second run's wall time, when its last FPN batch finished, when the city graph began
and ended (``CityRun.finish``: graph stitching, confidence, the vector files), and its summary's
seconds per stage (each on the thread that ran it). ``--one-thread``: every network and PyTorch
on one thread (``torch.set_num_threads(1)``), as before the int8 FPN left a core on its own.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import torch


def main() -> None:
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if "--one-thread" in sys.argv:
        torch.set_num_threads(1)  # ONNX Runtime's sessions take their thread count from it: the FPN on one core
    from csboundary.data.raster import Mosaic
    from csboundary.pipeline.jobs.prediction_run import run_prediction
    from csboundary.pipeline.prediction import city, city_job
    from csboundary.pipeline.prediction.options import PredictionOptions
    from csboundary.pipeline.prediction.patch import PatchPredictor

    moments: dict[str, float] = {}
    start = [0.0]

    def timed(cls, name: str, label: str):
        method = getattr(cls, name)

        def wrapper(self, *a, **k):
            moments.setdefault(f"{label} starts", time.perf_counter() - start[0])
            out = method(self, *a, **k)
            moments[f"{label} ends"] = time.perf_counter() - start[0]
            return out

        setattr(cls, name, wrapper)

    timed(city_job.CityJob, "compute_maps", "FPN")
    timed(city.CityRun, "finish", "city graph")
    town, precision = Path(args[0]), (args[1] if len(args) > 1 else "auto")
    predictor = PatchPredictor.load(None, torch.device("cpu"))
    predictor.use_precision(precision)
    predictor.use_engine("onnx", None)
    with Mosaic.open(town / "tiles") as mosaic, tempfile.TemporaryDirectory() as tmp:
        run_prediction(mosaic, predictor, Path(tmp) / "warm-up", PredictionOptions(progress=False))
        moments.clear()
        start[0] = time.perf_counter()
        _, summary = run_prediction(mosaic, predictor, Path(tmp) / "run", PredictionOptions(progress=False))
        print(
            json.dumps(
                {
                    "precision": predictor.precision,
                    "network_threads": predictor.onnx.thread_count,
                    "wall_s": round(time.perf_counter() - start[0], 3),
                    "moments_s": {k: round(v, 3) for k, v in moments.items()},
                    "patches": summary["patches"],
                    "seconds": summary["seconds"],
                    "core_seconds_per_patch": summary["core_seconds_per_patch"],
                },
                indent=1,
            )
        )


if __name__ == "__main__":
    main()
