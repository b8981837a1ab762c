"""Scores of one weights bundle when connected pieces shorter than L px are dropped from the city
graph, for a grid of L: the measurement behind the bundle's ``min_fragment_px``.

    python experiments/scripts/sweep_fragments.py WEIGHTS SET_OR_CITY... [--lengths 0,40,80,120,160,240]

Each city is predicted once; each L filters that graph and scores it at city scale (a SET, a
folder of cities from ``csboundary import-masks``, by the mean over its cities, as evaluate-set).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import torch

from csboundary.data import city_layout
from csboundary.graph import BoundaryGraph
from csboundary.graph.fragments import drop_short_fragments
from csboundary.metrics import evaluate
from csboundary.pipeline.prediction.city_scores import predicted_city, set_cities
from csboundary.pipeline.prediction.patch import PatchPredictor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("sets", nargs="+")
    parser.add_argument("--lengths", default="0,40,80,120,160,240")
    args = parser.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    predictor.settings = dataclasses.replace(predictor.settings, min_fragment_px=0.0)  # the sweep sets it
    lengths = [float(v) for v in args.lengths.split(",")]
    table = {}
    for s in args.sets:
        cities = [Path(s)] if city_layout.is_city_dir(s) else set_cities(s)
        runs = [predicted_city(c, predictor, assume_model_gsd=True) for c in cities]
        for length in lengths:
            metrics = [
                evaluate(
                    drop_short_fragments(r.graph, length),
                    BoundaryGraph.from_world_lines(lines, r.grid.transform),
                    scale="city",
                    seed=0,
                    extent=(0, 0, r.grid.width, r.grid.height),
                )["metrics"]
                for r, lines in runs
            ]
            table[s, length] = {
                k: float(np.mean([np.nan_to_num(m[k]) for m in metrics]))
                for k in ("precision@5", "recall@5", "f1@5", "apls", "tlts")
            }
        print(f"{Path(s).name}: predicted {len(cities)} cities", flush=True)
    print("L_px  " + " ".join(f"{Path(s).name[:16]:>16s}:P5/R5/F1@5/APLS/TLTS" for s in args.sets))
    for length in lengths:
        row = [table[s, length] for s in args.sets]
        cells = (
            f"{m['precision@5']:.3f}/{m['recall@5']:.3f}/{m['f1@5']:.3f}/{m['apls']:.3f}/{m['tlts']:.3f}".rjust(38)
            for m in row
        )
        print(f"{length:5.0f} " + " ".join(cells))


if __name__ == "__main__":
    main()
