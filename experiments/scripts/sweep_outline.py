"""Scores of one weights bundle on validation sets for a grid of roadway-outline settings.

    python experiments/scripts/sweep_outline.py WEIGHTS SET_OR_CITY... --grid "sure=0.65,level=0.5" "sure=0.8" ...

Each grid entry sets fields of :class:`csboundary.graph.outline_fusion.OutlineConfig` (``sure=0``
turns the outline off: the bundle's graph) and, as ``surface.strong=0.3``, of the surface check;
every other setting is the bundle's. Each SET is a
folder of cities (``csboundary import-masks``) scored by ``evaluate-set``'s mean, or one city
directory scored at city scale. Prints F1@5 / P@5 / APLS / TLTS per set: the measurement behind
the shipped outline setting (docs/real-imagery.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from csboundary.data import city_layout
from csboundary.pipeline.evaluation.evaluate_set import evaluate_set
from csboundary.pipeline.prediction.city_scores import evaluate_city_dir
from csboundary.pipeline.prediction.patch import load_predictor


def parsed(entry: str) -> dict:
    """``"sure=0.65,level=0.5"`` -> {"sure": 0.65, "level": 0.5}."""
    return {key: float(value) for key, value in (item.split("=") for item in entry.split(",") if item)}


def with_entry(settings, entry: str):
    """``settings`` with an entry's fields: bare names are OutlineConfig's, ``surface.NAME`` the
    surface check's (SurfaceCheckConfig)."""
    fields = parsed(entry)
    outline = {k: v for k, v in fields.items() if "." not in k}
    check = {k.split(".", 1)[1]: v for k, v in fields.items() if k.startswith("surface.")}
    return dataclasses.replace(
        settings,
        outline=dataclasses.replace(settings.outline, **outline),
        surface=dataclasses.replace(settings.surface, **check),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("sets", nargs="+")
    parser.add_argument(
        "--grid", nargs="+", required=True, help="OutlineConfig fields per row, e.g. sure=0.65,level=0.5"
    )
    args = parser.parse_args()
    predictor = load_predictor(
        args.weights, "cpu", precision="auto"
    )  # the command line's engine and precision (int8 on a CPU)
    base = predictor.settings
    print("setting", *args.sets, sep=" | ")
    for entry in args.grid:
        start = time.perf_counter()
        predictor.settings = with_entry(base, entry)
        row = []
        for s in args.sets:
            m = (
                evaluate_city_dir(Path(s), predictor)["metrics"]
                if city_layout.is_city_dir(s)
                else evaluate_set(s, predictor, progress=False)["mean"]
            )
            row.append(f"{m['f1@5']:.3f}/{m['precision@5']:.3f}/{m['apls']:.3f}/{m['tlts']:.3f}")
        print(entry, *row, f"{time.perf_counter() - start:.0f} s", sep=" | ", flush=True)


if __name__ == "__main__":
    main()
