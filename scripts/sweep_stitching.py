"""City-scale scores of one weights bundle for a grid of stitching settings: the measurement
behind ``StitchConfig.mend_px`` (docs/city-inference.md, "Seam mending").

    python scripts/sweep_stitching.py WEIGHTS CITY... --settings "5,8,5;15,8,5"

Each setting is ``mend_px,border_px,snap_px``; every city is predicted again per setting (the
stitching runs inside the city pipeline). Prints F1@5 / APLS / TLTS per city and setting.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from csboundary.graph import BoundaryGraph
from csboundary.graph.stitching import StitchConfig
from csboundary.metrics import evaluate
from csboundary.pipeline.evaluate_set import predicted_city
from csboundary.pipeline.patch import PatchPredictor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("cities", nargs="+")
    parser.add_argument("--settings", default="5,8,5;15,8,5", help="mend_px,border_px,snap_px;...")
    args = parser.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    print("mend border snap  " + "  ".join(f"{Path(c).name[:17]:>17s}" for c in args.cities))
    for setting in args.settings.split(";"):
        mend, border, snap = (float(v) for v in setting.split(","))
        stitch = StitchConfig(mend_px=mend, border_px=border, snap_px=snap)
        row = []
        for c in args.cities:
            run, lines = predicted_city(Path(c), predictor, assume_model_gsd=True, stitch=stitch)
            gt = BoundaryGraph.from_world_lines(lines, run.grid.transform)
            m = evaluate(run.graph, gt, scale="city", seed=0, extent=(0, 0, run.grid.width, run.grid.height))["metrics"]
            row.append(f"{m['f1@5']:.3f}/{m['apls']:.3f}/{m['tlts']:.3f}")
        print(f"{mend:4.0f} {border:6.0f} {snap:4.0f}  " + "  ".join(f"{r:>17s}" for r in row), flush=True)


if __name__ == "__main__":
    main()
