"""Experiment: predict labelled cities once and keep each edge's evidence and label, so that edge
confidence models can be compared without predicting again (docs/confidence.md).

    .venv/bin/python experiments/scripts/confidence_evidence.py --out runs/confidence/evidence CITY_OR_SET... [--weights W]

Writes one ``<city>.npz`` per city: ``evidence`` (E, F) in the order of
``csboundary.graph.edge_evidence.FEATURES``, ``truth_share``, ``length`` (px), ``kinds``.
Cities already written are skipped.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from csboundary.data import city_layout
from csboundary.pipeline.prediction.city_scores import set_cities
from csboundary.pipeline.prediction.patch import load_predictor
from csboundary.pipeline.training.confidence_fit import city_edges


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("cities", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--weights", type=Path, default=None)
    parser.add_argument("--prefix", default="", help="prefix of the file names (e.g. the set's name)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    predictor = load_predictor(args.weights, "cpu")
    found: list[Path] = []
    for path in args.cities:
        found += [path] if city_layout.is_city_dir(path) else set_cities(path)
    for city in found:
        target = args.out / f"{args.prefix}{city.name}.npz"
        if target.exists():
            continue
        edges = city_edges(city, predictor, assume_model_gsd=True)
        np.savez(
            target,
            evidence=edges.evidence if edges.evidence is not None else np.zeros((0, 0)),
            truth_share=edges.truth_share,
            length=edges.graph.edge_lengths(),
            kinds=np.array(edges.graph.edge_kinds or [], dtype=str),
        )
        print(
            f"{target}: {edges.graph.n_edges} edges, {edges.positive.mean() if len(edges.positive) else float('nan'):.2f} true",
            flush=True,
        )


if __name__ == "__main__":
    main()
