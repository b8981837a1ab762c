"""Fitting a bundle's edge confidence on labelled cities (``csboundary fit-confidence``).

Each city is predicted exactly as ``predict`` predicts it, with the maps of every core kept; each
edge of the city graph gets its evidence (:mod:`csboundary.graph.edge_evidence`) and its label,
true when at least half its length lies within 5 px of the city's ground truth
(:func:`csboundary.metrics.confidence.edge_truth`). The confidence model is fitted on all cities
(:func:`csboundary.models.confidence.fit_edge_confidence`, cities held out together for its
calibration) and written into a copy of the bundle with its provenance.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from csboundary.data import city as layout
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.edge_evidence import FEATURES, MAP_FEATURES
from csboundary.metrics.confidence import TRUE_SHARE, edge_truth
from csboundary.models.checkpoint import code_version, file_sha256, load_checkpoint, save_checkpoint
from csboundary.models.confidence import EdgeConfidence, fit_edge_confidence
from csboundary.pipeline.evaluate_set import predicted_city
from csboundary.pipeline.patch import PatchPredictor


TREE_SHARE = 0.7  # the trees learn to rank edges mostly on the ground truth; the calibration then targets TRUE_SHARE


@dataclass
class CityEdges:
    """The edges of one predicted city: evidence, share of length on the ground truth, length."""

    name: str
    graph: BoundaryGraph
    evidence: np.ndarray
    truth_share: np.ndarray

    @property
    def positive(self) -> np.ndarray:
        return self.truth_share >= TRUE_SHARE


def city_edges(city_dir: str | Path, predictor: PatchPredictor, assume_model_gsd: bool = False) -> CityEdges:
    """Predict a labelled city (without any confidence of the bundle's) and label its edges."""
    confidence, collect = predictor.confidence, predictor.collect_evidence
    predictor.confidence, predictor.collect_evidence = None, True
    try:
        result, lines = predicted_city(city_dir, predictor, assume_model_gsd=assume_model_gsd)
    finally:
        predictor.confidence, predictor.collect_evidence = confidence, collect
    gt = BoundaryGraph.from_world_lines(list(lines), result.grid.transform)
    return CityEdges(Path(city_dir).name, result.graph, result.evidence, edge_truth(result.graph, gt))


def check_learnable(cities: list[Path], per_city: list[CityEdges]) -> None:
    """InputError unless the cities give what a fit needs: edges in at least two cities (the
    calibration holds cities out in turn) and both true and false edges (the trees need two classes)."""
    named = ", ".join(str(c) for c in cities[:3]) + (" ..." if len(cities) > 3 else "")
    with_edges = [c for c in per_city if c.graph.n_edges]
    if len(with_edges) < 2:
        raise InputError(named, f"{len(with_edges)} of {len(cities)} cities gave predicted edges; the confidence is calibrated on "
                                "cities held out in turn, so it needs at least two")
    positive = sum(int(c.positive.sum()) for c in with_edges)
    if positive == 0:
        raise InputError(named, "no predicted edge lies on the ground truth (is the ground truth empty, or in another place?): "
                                "nothing to learn a true edge from")
    if positive == sum(c.graph.n_edges for c in with_edges):
        raise InputError(named, "every predicted edge lies on the ground truth: nothing to learn a false edge from")


def fit_bundle_confidence(cities: list[Path], weights: Path, out: Path, predictor: PatchPredictor, seed: int = 0,
                          progress: bool = True, n_trees: int = 200, depth: int = 2,
                          assume_model_gsd: bool = False) -> tuple[EdgeConfidence, list[CityEdges]]:
    """Fit the confidence on ``cities`` with ``predictor`` (the bundle ``weights``) and write the
    bundle with it to ``out``; returns the model and each city's labelled edges.
    ``assume_model_gsd``: imagery without a pixel size is at the model's (imported crops)."""
    payload = load_checkpoint(weights, ("bundle",))
    per_city = [city_edges(c, predictor, assume_model_gsd) for c in tqdm(cities, desc="predict cities", unit="city", disable=not progress)]
    check_learnable(cities, per_city)
    per_city = [c for c in per_city if c.graph.n_edges]
    features = tuple(f for f in FEATURES if not ("surface" in f and not predictor.fpn.config.surface))
    evidence = np.concatenate([c.evidence for c in per_city])
    positive = np.concatenate([c.positive for c in per_city])
    groups = np.concatenate([np.full(c.graph.n_edges, k) for k, c in enumerate(per_city)])
    provenance = {"weights": str(weights), "weights_sha256": file_sha256(weights), "seed": seed, "code_version": code_version(),
                  "cities": [{"dir": str(c), "ground_truth_sha256": file_sha256(layout.ground_truth_path(c))} for c in cities],
                  "map_features": [f for f in features if f in MAP_FEATURES]}
    mostly_true = np.concatenate([c.truth_share >= TREE_SHARE for c in per_city])
    provenance["tree_share"] = TREE_SHARE
    model = fit_edge_confidence(evidence, positive, groups, features, n_trees=n_trees, depth=depth, seed=seed, provenance=provenance,
                                tree_positive=mostly_true)
    payload = {k: v for k, v in payload.items() if k not in ("format", "kind")}
    payload["confidence"] = model.to_dict()
    save_checkpoint(out, "bundle", **payload)
    return model, per_city
