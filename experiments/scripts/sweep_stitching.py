"""City-scale scores of one weights bundle for a grid of stitching settings: the measurement
behind ``StitchConfig.mend_px`` and ``node_shared`` and the bundle's ``attach_max_px``
(docs/city-inference.md).

    python experiments/scripts/sweep_stitching.py WEIGHTS CITY_OR_SET... --settings "15,8,5,0,0;15,8,5,40,1"

Each setting is ``mend_px,border_px,snap_px,attach_px,node_shared`` (a shorter setting keeps the
defaults of the fields it leaves out). Every city is predicted once; its patch graphs are
stitched again per setting (stitching sees nothing else). A SET (``csboundary import-masks``)
is expanded to its cities and also gets a mean row. Prints F1@5 / APLS / TLTS per city and
setting.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import torch

from csboundary.data import city_layout
from csboundary.graph import BoundaryGraph
from csboundary.graph.stitching import StitchConfig
from csboundary.metrics import evaluate
from csboundary.pipeline.prediction.city import city_graph
from csboundary.pipeline.prediction.city_scores import predicted_city, set_cities
from csboundary.pipeline.prediction.patch import PatchPredictor

FIELDS = ("mend_px", "border_px", "snap_px", "attach_px", "node_shared")


def parse_setting(text: str) -> tuple[StitchConfig, float | None]:
    """The stitching of a setting and its attachment radius (None: the bundle's)."""
    values = dict(zip(FIELDS, (float(v) for v in text.split(","))))
    attach = values.pop("attach_px", None)
    changes = {name: (bool(v) if name == "node_shared" else v) for name, v in values.items()}
    return dataclasses.replace(StitchConfig(), **changes), attach


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("cities", nargs="+", help="city folders, or sets of them")
    parser.add_argument("--settings", default="15,8,5,0,0;15,8,5,40,1", help=";-separated " + ",".join(FIELDS))
    args = parser.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    settings = [parse_setting(s) for s in args.settings.split(";")]
    print("setting (" + ",".join(FIELDS) + ")  then per city F1@5 / APLS / TLTS")
    rows: dict[str, list[np.ndarray]] = {s: [] for s in args.settings.split(";")}
    for given in args.cities:
        is_city = (Path(given) / "city.json").exists() and city_layout.ground_truth_path(Path(given)).exists()
        for city in [Path(given)] if is_city else set_cities(given):
            run, lines = predicted_city(city, predictor, assume_model_gsd=True)
            gt = BoundaryGraph.from_world_lines(lines, run.grid.transform)
            parts = []
            for text, (stitch, attach) in zip(rows, settings):
                graph = city_graph(
                    run.patch_graphs,
                    run.grid,
                    stitch,
                    run.graph.crs,
                    predictor.settings.min_fragment_px,
                    predictor.settings.attach_px if attach is None else attach,
                )
                m = evaluate(graph, gt, scale="city", seed=0, extent=(0, 0, run.grid.width, run.grid.height))["metrics"]
                rows[text].append(np.array([m["f1@5"], m["apls"], m["tlts"]]))
                parts.append(f"{text}: {m['f1@5']:.3f}/{m['apls']:.3f}/{m['tlts']:.3f}")
            print(f"{city.name:28s} " + "  ".join(parts), flush=True)
    if sum(len(v) for v in rows.values()) > len(rows):
        print(
            f"{'mean':28s} "
            + "  ".join(f"{t}: " + "/".join(f"{x:.3f}" for x in np.mean(v, axis=0)) for t, v in rows.items())
        )


if __name__ == "__main__":
    main()
