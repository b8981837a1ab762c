"""FPN alone against the whole pipeline, for the default engine (what ``predict`` runs: ``--engine
auto --precision auto``), the torch engine, float32 ONNX and int8 ONNX, in one run.

    .venv/bin/python benchmarks/engine_speed.py [CITY] [--repeat 1] [--weights BUNDLE] [--bfloat16] [--fpn-threads 1]

CITY defaults to data/cities/test-s7-2x2-2000 (4000 x 4000 px, 16 patches; synthesized if
missing). For each engine, in this one process: the FPN alone on every patch's window (read
beforehand, batch 1: the network's time and nothing else), then ``run_prediction`` end to end on
the same city (reading, FPN, map stitching, vertices, AfANet, graph stitching, every output
file). ``--bfloat16`` adds a row: the onnx engine with that ``--precision``. Prints seconds per
patch of both, their ratio (acceptance: at most 1.2), km2/h, the stage table, the core seconds per
patch of both (every thread of the process: what the rest of the pipeline costs beside the FPN,
and the lowest ratio a perfect overlap could reach on this machine's cores), the core seconds per
patch of each stage (``--fpn-threads 1``: the FPN on one core, everything else on the other, every
stage's work on the thread that ran it), and whether the two engines' graph.json are identical
(and the largest difference in vertex count and edge count when not).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from csboundary.data.grid import PatchGrid
from csboundary.data.raster import Mosaic
from csboundary.pipeline.jobs.prediction_run import run_prediction
from csboundary.pipeline.outputs.run_summary import stage_table
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.patch import PatchPredictor


def fpn_only(predictor: PatchPredictor, images: list, repeat: int) -> tuple[float, float]:
    """Wall seconds and core seconds (every thread of the process) per patch of the FPN alone."""
    predictor.patch_maps([None], [images[0]])  # warm-up (first-call allocations, session set-up)
    start, cores = time.perf_counter(), time.process_time()
    for _ in range(repeat):
        for image in images:
            predictor.patch_maps([None], [image])
    n = repeat * len(images)
    return (time.perf_counter() - start) / n, (time.process_time() - cores) / n


def cores_available() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city", nargs="?", type=Path, default=Path("data/cities/test-s7-2x2-2000"))
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--weights", default=None, help="weights bundle (default: the shipped one)")
    parser.add_argument(
        "--bfloat16",
        action="store_true",
        help="also the onnx engine with --precision bfloat16 (the FPN in PyTorch under bfloat16 autocast)",
    )
    parser.add_argument(
        "--fpn-threads",
        type=int,
        default=None,
        help="threads for the networks (1: the FPN on one core, the rest of the pipeline on another)",
    )
    args = parser.parse_args()
    if args.fpn_threads:
        torch.set_num_threads(args.fpn_threads)  # ONNX Runtime's sessions take their thread count from it
    if not (args.city / "city.json").exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "csboundary",
                "synth",
                str(args.city),
                "--seed",
                "7",
                "--split",
                "test",
                "--tiles",
                "2x2",
                "--tile-size",
                "2000",
                "--quiet",
            ],
            check=True,
        )
    rows = {}
    with tempfile.TemporaryDirectory() as tmp, Mosaic.open(args.city / "tiles") as mosaic:
        grid = PatchGrid.for_mosaic(mosaic)
        images = [mosaic.read(p.expanded).data for p in grid]
        extra = ("onnx+int8",) + (("onnx+bfloat16",) if args.bfloat16 else ())
        for engine in ("default", "torch", "onnx") + extra:
            predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
            if engine == "default":  # as predict runs with no option given
                predictor.use_precision("auto")
                predictor.use_engine("auto", args.weights)
                print(f"default: the {predictor.engine} engine, FPN in {predictor.precision_choice}", flush=True)
            else:
                predictor.use_precision(
                    engine.split("+")[1] if "+" in engine else "float32"
                )  # before the engine: int8 is made there
                predictor.use_engine(engine.split("+")[0], args.weights)
            fpn, fpn_cores = fpn_only(predictor, images, args.repeat)
            out = Path(tmp) / engine
            cores = time.process_time()
            _, summary = run_prediction(
                mosaic, predictor, out, PredictionOptions(progress=False), settings={"engine": engine}
            )
            n = summary["patches"]
            total, run_cores = summary["seconds"]["total"] / n, (time.process_time() - cores) / n
            rows[engine] = (fpn, total, summary, (out / "graph.json").read_bytes())
            # What the FPN leaves to share: the rest's core seconds, and the ratio even a perfect
            # overlap on this machine's cores could not beat (both networks' work at full use).
            rest = run_cores - fpn_cores
            bound = max(1.0, run_cores / (cores_available() * fpn))
            print(
                f"{engine}: FPN alone {fpn:.3f} s/patch, end to end {total:.3f} s/patch, ratio {total / fpn:.2f} (limit 1.2), "
                f"{summary['km2_per_hour']} km2/h\n       {stage_table(summary)}\n"
                f"       core s/patch: FPN alone {fpn_cores:.3f}, end to end {run_cores:.3f}, the rest {rest:.3f}; "
                f"ratio with a perfect overlap on {cores_available()} cores {bound:.2f}\n"
                f"       core s/patch by stage (the thread that ran it; whole with one thread per network): "
                + ", ".join(f"{k.replace('_', ' ')} {v:.3f}" for k, v in summary["core_seconds_per_patch"].items())
                + "; post-processing (all but the FPN) "
                f"{sum(v for k, v in summary['core_seconds_per_patch'].items() if k != 'fpn'):.3f}",
                flush=True,
            )
    (tf, _, ts, tg), (of, _, os_, og) = rows["torch"], rows["onnx"]
    print(
        f"onnx / torch end-to-end throughput: {os_['km2_per_hour'] / ts['km2_per_hour']:.2f}x; FPN alone {tf / of:.2f}x faster"
    )
    for engine in ("default",) + extra:
        ef, _, es, _ = rows[engine]
        print(
            f"{engine} / torch end-to-end throughput: {es['km2_per_hour'] / ts['km2_per_hour']:.2f}x; "
            f"FPN alone {tf / ef:.2f}x faster"
        )
    if tg == og:
        print("graph.json identical for both engines")
    else:
        a, b = json.loads(tg), json.loads(og)
        print(
            f"graph.json differs: {len(a['vertices'])} vs {len(b['vertices'])} vertices, "
            f"{len(a['edges'])} vs {len(b['edges'])} edges"
        )


if __name__ == "__main__":
    main()
