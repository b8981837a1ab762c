"""Experiment: how well a bundle's edge confidence serves a reviewer on labelled sets: AUC, ECE and
the least sure 20 % of edges, as a share of all false edges and of what any order could put
there, by edges and by length (docs/confidence.md). Edges are pooled over each set's cities.

    .venv/bin/python experiments/scripts/confidence_review.py NAME=SET_OR_CITY... [--weights W] [--json OUT]

Synthetic test cities of every style, one each (seed 7, test split):

    for s in classic grid downtown dense suburb rural irregular residential leafy highway; do
      csboundary synth data/conf-test/$s --seed 7 --split test --style $s --tiles 1x1 --tile-size 2500; done
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from csboundary.data import city_layout
from csboundary.metrics.confidence_quality import confidence_report
from csboundary.models.checkpoint import load_checkpoint, shipped_weights
from csboundary.models.confidence_model import EdgeConfidence
from csboundary.pipeline.prediction.city_scores import set_cities
from csboundary.pipeline.prediction.patch import load_predictor
from csboundary.pipeline.training.confidence_fit import city_edges


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("sets", nargs="+", help="NAME=PATH: a set folder or a city directory")
    parser.add_argument("--weights", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    weights = args.weights or shipped_weights()
    predictor = load_predictor(weights, "cpu")
    table = EdgeConfidence.from_dict(load_checkpoint(weights, ("bundle",))["confidence"], weights)
    out = {}
    print(
        f"{'set':22s} {'edges':>6s} {'true':>5s} {'AUC':>6s} {'ECE':>6s}   "
        "least sure 20 %: false edges (of attainable), false length "
        f"(of attainable)"
    )
    for item in args.sets:
        name, path = item.split("=", 1)
        path = Path(path)
        cities = [path] if city_layout.is_city_dir(path) else set_cities(path)
        found = [city_edges(c, predictor, assume_model_gsd=True) for c in cities]
        found = [e for e in found if e.graph.n_edges]
        p = np.concatenate([table.probability(e.evidence) for e in found])
        share = np.concatenate([e.truth_share for e in found])
        length = np.concatenate([e.graph.edge_lengths() for e in found])
        r = confidence_report(p, share, length)
        out[name] = r
        v = r["review"]["0.2"]
        print(
            f"{name:22s} {r['edges']:6d} {r['share_true']:5.2f} {r['auc']:6.3f} {r['ece']:6.3f}   "
            f"{v['false_edges']:.2f} ({v['false_edges_of_attainable']:.2f}), {v['false_length']:.2f} "
            f"({v['false_length_of_attainable']:.2f})",
            flush=True,
        )
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main()
