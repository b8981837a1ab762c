"""Why a bundle's APLS pairs fail, per city: the share of the paper's ground-truth pairs whose
ends find no predicted vertex within the snap radius (unmatched), whose ends snap onto two
different connected pieces (disconnected), whose predicted path is more than twice as long (too
long), and the summed cost of the rest; APLS = 1 - the four shares.

    python experiments/scripts/apls_failures.py WEIGHTS SET_OR_CITY...

A SET (``csboundary import-masks``) prints one line per city and the mean. The diagnosis behind
the seam-mending radius (docs/city-inference.md) and the model card's remarks on suburb.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from csboundary.data import city_layout
from csboundary.graph import BoundaryGraph
from csboundary.metrics import apls_paper_pairs
from csboundary.metrics.apls import pair_costs
from csboundary.pipeline.prediction.city_scores import predicted_city, set_cities
from csboundary.pipeline.prediction.patch import PatchPredictor

COLUMNS = ("unmatched", "disconnected", "too long", "path cost")


def failure_shares(pred: BoundaryGraph, gt: BoundaryGraph) -> np.ndarray:
    """(4,) shares of the paper's APLS cost (seed 0) by cause, in the order of ``COLUMNS``."""
    pairs = apls_paper_pairs(pred, gt)
    if pairs.n_pairs == 0:
        return np.full(4, np.nan)
    finite = np.isfinite(pairs.pred_length)
    cost = pair_costs(pairs.gt_length, pairs.pred_length)
    counts = [
        (~pairs.matched).sum(),
        (pairs.matched & ~pairs.connected).sum(),
        (pairs.connected & ~finite).sum(),
        cost[finite].sum(),
    ]
    return np.array(counts, float) / pairs.n_pairs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("sets", nargs="+")
    args = parser.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    print(f"{'city':28s} " + " ".join(f"{c:>12s}" for c in COLUMNS) + "         APLS")
    for s in args.sets:
        cities = [Path(s)] if city_layout.is_city_dir(s) else set_cities(s)
        rows = []
        for c in cities:
            run, lines = predicted_city(c, predictor, assume_model_gsd=True)
            rows.append(failure_shares(run.graph, BoundaryGraph.from_world_lines(lines, run.grid.transform)))
            if len(cities) > 1:
                print(f"  {c.name:26s} " + " ".join(f"{v:12.3f}" for v in rows[-1]) + f" {1 - rows[-1].sum():12.3f}")
        mean = np.nanmean(rows, axis=0)
        print(
            f"{Path(s).name[:28]:28s} " + " ".join(f"{v:12.3f}" for v in mean) + f" {1 - mean.sum():12.3f}", flush=True
        )


if __name__ == "__main__":
    main()
