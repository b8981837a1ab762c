"""City-scale scores of one weights bundle for several settings of the window's backed
attachment (``--attach-backed``; docs/city-inference.md, "Backed attachment in the window").

    python scripts/sweep_attach_backed.py WEIGHTS "0,60,100,60:0.6:3" CITY_OR_SET...

Each setting is ``attach_px[:min_support[:max_gap_px]]`` (the support thresholds are the end
joining's, shared with the joins between ends). The attachment runs in every window, so each
city is predicted again per setting. A SET (``csboundary import-masks``) is expanded to its
cities; the last line is the mean over every city. Prints F1@5 / APLS / TLTS.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import torch

from csboundary.data import city as layout
from csboundary.graph import BoundaryGraph
from csboundary.metrics import evaluate
from csboundary.pipeline.evaluate_set import predicted_city, set_cities
from csboundary.pipeline.patch import PatchPredictor


def parse_setting(text: str) -> dict:
    names = ("attach_px", "min_support", "max_gap_px")
    return dict(zip(names, (float(v) for v in text.split(":"))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("settings", help="comma-separated attach_px[:min_support[:max_gap_px]]")
    parser.add_argument("cities", nargs="+", help="city folders, or sets of them")
    parser.add_argument("--engine", default="auto", help="auto | torch | onnx")
    args = parser.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    predictor.use_engine(args.engine, args.weights)
    settings = args.settings.split(",")
    rows: dict[str, list[list[float]]] = {s: [] for s in settings}
    for given in args.cities:
        is_city = (Path(given) / "city.json").exists() and layout.ground_truth_path(Path(given)).exists()
        for city in [Path(given)] if is_city else set_cities(given):
            parts = []
            for text in settings:
                predictor.join = dataclasses.replace(predictor.join, **parse_setting(text))
                run, lines = predicted_city(city, predictor, assume_model_gsd=True)
                gt = BoundaryGraph.from_world_lines(lines, run.grid.transform)
                m = evaluate(run.graph, gt, scale="city", seed=0, extent=(0, 0, run.grid.width, run.grid.height))["metrics"]
                rows[text].append([m["f1@5"], m["apls"], m["tlts"]])
                parts.append(f"{text}: {m['f1@5']:.3f}/{m['apls']:.3f}/{m['tlts']:.3f}")
            print(f"{city.name:28s} " + "  ".join(parts), flush=True)
    print(f"{'mean':28s} " + "  ".join(f"{t}: " + "/".join(f"{x:.3f}" for x in np.mean(v, axis=0)) for t, v in rows.items()))


if __name__ == "__main__":
    main()
