"""Fitting a bundle's edge confidence on labelled cities (``csboundary fit-confidence``).

Each city is predicted exactly as ``predict`` predicts it, with the maps of every core kept; each
edge of the city graph gets its evidence (:mod:`csboundary.graph.edge_evidence`) and its label,
true when at least half its length lies within 5 px of the city's ground truth
(:func:`csboundary.metrics.confidence_quality.edge_truth`). The confidence model is fitted on all cities
(:func:`csboundary.models.confidence_model.fit_edge_confidence`, cities held out together for its
calibration) and written into a copy of the bundle with its provenance.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from csboundary.data import city_layout
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.edge_evidence import FEATURES, MAP_FEATURES
from csboundary.metrics.confidence_quality import TRUE_SHARE, edge_truth
from csboundary.models.checkpoint import code_version, file_sha256, load_checkpoint, save_checkpoint
from csboundary.models.confidence_model import EdgeConfidence, fit_edge_confidence
from csboundary.pipeline.prediction.city_scores import predicted_city
from csboundary.pipeline.prediction.patch import PatchPredictor

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
        raise InputError(
            named,
            f"{len(with_edges)} of {len(cities)} cities gave predicted edges; the confidence is calibrated on "
            "cities held out in turn, so it needs at least two",
        )
    positive = sum(int(c.positive.sum()) for c in with_edges)
    if positive == 0:
        raise InputError(
            named,
            "no predicted edge lies on the ground truth (is the ground truth empty, or in another place?): "
            "nothing to learn a true edge from",
        )
    if positive == sum(c.graph.n_edges for c in with_edges):
        raise InputError(named, "every predicted edge lies on the ground truth: nothing to learn a false edge from")


def fit_bundle_confidence(
    cities: list[Path],
    weights: Path,
    out: Path,
    predictor: PatchPredictor,
    seed: int = 0,
    progress: bool = True,
    n_trees: int = 200,
    depth: int = 2,
    assume_model_gsd: bool = False,
    known: dict[Path, CityEdges] | None = None,
) -> tuple[EdgeConfidence, list[CityEdges]]:
    """Fit the confidence on ``cities`` with ``predictor`` (the bundle ``weights``) and write the
    bundle with it to ``out``; returns the model and each city's labelled edges (``known``:
    those already predicted with ``predictor``, by city). ``assume_model_gsd``: imagery without
    a pixel size is at the model's (imported crops)."""
    payload = load_checkpoint(weights, ("bundle",))
    known = known or {}
    per_city = [
        known[c] if c in known else city_edges(c, predictor, assume_model_gsd)
        for c in tqdm(cities, desc="predict cities", unit="city", disable=not progress)
    ]
    check_learnable(cities, per_city)
    per_city = [c for c in per_city if c.graph.n_edges]
    features = tuple(f for f in FEATURES if not ("surface" in f and not predictor.fpn.config.surface))
    evidence = np.concatenate([c.evidence for c in per_city])
    positive = np.concatenate([c.positive for c in per_city])
    groups = np.concatenate([np.full(c.graph.n_edges, k) for k, c in enumerate(per_city)])
    provenance = {
        "weights": str(weights),
        "weights_sha256": file_sha256(weights),
        "seed": seed,
        "code_version": code_version(),
        "cities": [
            {"dir": str(c), "ground_truth_sha256": file_sha256(city_layout.ground_truth_path(c))} for c in cities
        ],
        "map_features": [f for f in features if f in MAP_FEATURES],
    }
    mostly_true = np.concatenate([c.truth_share >= TREE_SHARE for c in per_city])
    provenance["tree_share"] = TREE_SHARE
    model = fit_edge_confidence(
        evidence,
        positive,
        groups,
        features,
        n_trees=n_trees,
        depth=depth,
        seed=seed,
        provenance=provenance,
        tree_positive=mostly_true,
    )
    payload = {k: v for k, v in payload.items() if k not in ("format", "kind")}
    payload["confidence"] = model.to_dict()
    save_checkpoint(out, "bundle", **payload)
    return model, per_city


MIN_REFIT_EDGES = 100  # labelled edges a refit needs before it can speak for the user's imagery ...
MIN_REFIT_CLASS = 20  # ... with at least this many true and this many false among them


def refit_for_tuned(
    bundle: Path, labelled: list[Path], synthetic: list[Path], device, seed: int = 0, progress: bool = True
) -> dict:
    """Refit the edge confidence of a tuned ``bundle`` (in place) on its ``labelled`` cities and
    the ``synthetic`` cities it mixed in, predicted with the tuned networks, when the labelled
    cities give enough edges (``MIN_REFIT_EDGES``, of each kind ``MIN_REFIT_CLASS``); otherwise
    the bundle keeps the base's confidence. Returns what was done and why, for the provenance."""
    predictor = PatchPredictor.load(bundle, device)
    user = [
        city_edges(c, predictor, assume_model_gsd=True)
        for c in tqdm(labelled, desc="confidence: labelled cities", unit="city", disable=not progress)
    ]
    edges = sum(c.graph.n_edges for c in user)
    true = sum(int(c.positive.sum()) for c in user)
    record = {
        "labelled_edges": edges,
        "labelled_true_edges": true,
        "labelled_cities": len(labelled),
        "synthetic_cities": len(synthetic),
    }
    if edges < MIN_REFIT_EDGES or min(true, edges - true) < MIN_REFIT_CLASS:
        record["refitted"] = False
        record["reason"] = (
            f"the labelled cities give {edges} edges ({true} true, {edges - true} false); a refit needs at least "
            f"{MIN_REFIT_EDGES}, with {MIN_REFIT_CLASS} of each: the base bundle's confidence is kept"
        )
        return record
    fit_bundle_confidence(
        list(labelled) + list(synthetic),
        bundle,
        bundle,
        predictor,
        seed=seed,
        progress=progress,
        assume_model_gsd=True,
        known=dict(zip(labelled, user)),
    )
    record["refitted"] = True
    record["reason"] = (
        f"refitted with the tuned networks on {len(labelled)} labelled cities ({edges} edges, {true} true) "
        f"and {len(synthetic)} synthetic cities"
    )
    return record
