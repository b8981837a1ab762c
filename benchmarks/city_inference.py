"""City-scale inference with the shipped weights, end to end, and its scores at both scales.

Prints seconds per patch for each stage (read, FPN, map stitching, vertex extraction, AfANet,
graph stitching), throughput in km2/h, and precision/recall/F1 at 2/5/10 px, APLS and TLTS at
patch and city scale; writes every output of `csboundary predict` plus scores.json to OUT.

Usage: .venv/bin/python benchmarks/city_inference.py CITY_DIR OUT [--oracle] [--batch-size N] [--device D]
   e.g. csboundary synth data/cities/test-s0-2x2-5000 --seed 0 --tiles 2x2 --split test
        .venv/bin/python benchmarks/city_inference.py data/cities/test-s0-2x2-5000 out/bench-city
``--oracle`` feeds the ground truth's maps and adjacency through the same pipeline (the upper
bound the networks are measured against).
"""

from __future__ import annotations

import argparse
import json

from csboundary.data import city_layout
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.metrics.report import format_rows, write_scores
from csboundary.models.device import resolve_device
from csboundary.pipeline.evaluation.oracle import OracleModel
from csboundary.pipeline.jobs.prediction_run import run_prediction
from csboundary.pipeline.outputs.run_summary import stage_table
from csboundary.pipeline.prediction.city_scores import evaluate_run
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.patch import PatchPredictor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city")
    parser.add_argument("out")
    parser.add_argument("--oracle", action="store_true")
    parser.add_argument("--batch-size", type=int, default=1)
    parser.add_argument("--device", default="auto")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    with Mosaic.open(city_layout.tiles_dir(args.city)) as mosaic:
        lines = list(read_ground_truth(city_layout.ground_truth_path(args.city), mosaic.crs).geometry)
        model = (
            OracleModel.from_lines(lines, mosaic)
            if args.oracle
            else PatchPredictor.load(None, resolve_device(args.device))
        )
        settings = {
            "model": "oracle" if args.oracle else "shipped weights",
            "batch_size": args.batch_size,
            "city": args.city,
        }
        result, summary = run_prediction(
            mosaic,
            model,
            args.out,
            PredictionOptions(batch_size=args.batch_size),
            settings=settings,
            ground_truth=lines,
        )
    scores = evaluate_run(result, lines, seed=args.seed)
    write_scores(f"{args.out}/scores.json", scores)
    print(format_rows(scores))
    print(stage_table(summary))
    print(json.dumps({"counts": summary["counts"], "map_store_peak_mb": summary["map_store_peak_mb"]}))


if __name__ == "__main__":
    main()
