"""Probe: which edges should the road-surface check judge, and how? (measurement, not a feature)

    .venv/bin/python experiments/scripts/probe_surface_rules.py BUNDLE SETS... --rules kinds:skeleton:0.5,hyst:0.5:0.2

BUNDLE has an FPN with a surface head (its own surface check is turned off here). Each rule
filters every patch graph with the maps' surface channel:
``kinds:K1+K2:T`` drops edges of those kinds (normal, corner, skeleton) scoring below T;
``hyst:S:W`` is graph/surface_check.py's hysteresis over all edges. Prints F1@5/APLS/TLTS per set.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from sweep_edge_support import score_row  # noqa: E402

from csboundary.graph.surface_check import kept_by_hysteresis, side_surface  # noqa: E402
from csboundary.pipeline.prediction.patch import PatchPredictor  # noqa: E402

RULE = {"value": None}


def keep(graph, surface: np.ndarray, rule: str) -> np.ndarray:
    scores = side_surface(graph, surface, 8.0)
    parts = rule.split(":")
    if parts[0] == "hyst":
        return kept_by_hysteresis(graph.edges, graph.n_vertices, scores, float(parts[1]), float(parts[2]))
    kinds = set(parts[1].split("+"))
    judged = np.array([k in kinds for k in (graph.edge_kinds or ["normal"] * graph.n_edges)])
    return ~judged | (scores >= float(parts[2]))


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("bundle")
    p.add_argument("sets", nargs="+")
    p.add_argument("--rules", default="hyst:0.5:0.2")
    p.add_argument(
        "--symmetric", action="store_true", help="score APLS in the symmetric variant (it sees false boundaries)"
    )
    args = p.parse_args()
    if args.symmetric:
        import functools

        import csboundary.metrics as metrics

        metrics.evaluate = functools.partial(metrics.evaluate, apls="symmetric")
    predictor = PatchPredictor.load(args.bundle, torch.device("cpu"))
    # active: the maps carry the surface channel
    predictor.settings = dataclasses.replace(
        predictor.settings, surface=dataclasses.replace(predictor.settings.surface, strong=1e-9)
    )

    def finished(self, patch, maps, graph):  # the bundle's own check replaced by the rule
        graph = self.filled(patch, maps, graph)
        if RULE["value"] is None or graph.n_edges == 0:
            return graph
        return graph.edge_subgraph(keep(graph, maps[2], RULE["value"]))

    PatchPredictor.finished = finished
    for rule in args.rules.split(","):
        RULE["value"] = None if rule == "off" else rule
        row = score_row(args.sets, predictor)
        print(f"{rule:24s} " + " ".join(f"{r:>20s}" for r in row), flush=True)


if __name__ == "__main__":
    main()
