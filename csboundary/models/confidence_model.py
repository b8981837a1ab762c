"""The edge confidence: a calibrated probability that a predicted edge is a true road boundary
(at least half its length within 5 px of the ground truth; :mod:`csboundary.metrics.confidence_quality`).

It is computed from an edge's evidence (:mod:`csboundary.graph.edge_evidence`) by gradient-boosted
trees (scikit-learn's ``GradientBoostingClassifier``), whose raw output is then calibrated by an
isotonic regression fitted on out-of-fold predictions (cities held out in turn), so that among
edges given 0.3 about three in ten are true.

A weights bundle stores it as plain numbers under ``confidence`` (never a pickle: bundles load
with ``weights_only=True``): the feature names, every tree as arrays (feature, threshold, left
and right child, leaf value), the learning rate, and the isotonic breakpoints. Applying it needs
numpy only; fitting needs scikit-learn (``pip install 'csboundary[fit]'``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from csboundary.errors import InputError
from csboundary.graph.edge_evidence import FEATURES

VERSION = 1
TIE_BREAK = 1e-3  # inside a flat step of the isotonic map, edges are still ordered by the trees' raw output
MAX_NODES = 10**6
# a fitted table's leaves stay within tens of log-odds (the shipped one: 16.5) and its learning rate
# within (0, 1]: larger numbers are damage that would turn every probability into 0 or 1
MAX_LEAF = 1e3
MAX_LEARNING_RATE = 1.0


@dataclass(frozen=True)
class EdgeConfidence:
    """Trees over the named features -> raw log-odds -> isotonic map -> probability."""

    features: tuple[str, ...]
    learning_rate: float
    tree_starts: np.ndarray  # (T + 1,) where each tree's nodes begin in the arrays below
    feature: np.ndarray  # (N,) feature index of a split node (into ``features``), -1 at a leaf
    threshold: np.ndarray  # (N,) go left when the feature <= threshold
    left: np.ndarray  # (N,) child index within the tree, -1 at a leaf
    right: np.ndarray
    value: np.ndarray  # (N,) leaf value (raw log-odds contribution)
    iso_x: np.ndarray  # isotonic breakpoints: raw -> probability, linear between, clipped outside
    iso_y: np.ndarray
    provenance: dict = field(default_factory=dict)

    @property
    def n_trees(self) -> int:
        return len(self.tree_starts) - 1

    def raw(self, evidence: np.ndarray) -> np.ndarray:
        """(E,) the trees' summed output for (E, len(FEATURES)) evidence."""
        x = self.columns(evidence)
        total = np.zeros(len(x))
        rows = np.arange(len(x))
        for t in range(self.n_trees):
            start = self.tree_starts[t]
            node = np.zeros(len(x), np.int64)
            while True:
                split = self.left[start + node] >= 0
                if not split.any():
                    break
                f = self.feature[start + node[split]]
                go_left = x[rows[split], f] <= self.threshold[start + node[split]]
                node[split] = np.where(go_left, self.left[start + node[split]], self.right[start + node[split]])
            total += self.value[start + node]
        return self.learning_rate * total

    def probability(self, evidence: np.ndarray) -> np.ndarray:
        """(E,) calibrated probability that each edge is true."""
        raw = self.raw(evidence)
        p = np.interp(raw, self.iso_x, self.iso_y)
        return np.clip(
            p + TIE_BREAK * 0.5 * np.tanh(raw / 2), 0.0, 1.0
        )  # tanh: the logistic's centred form, free of overflow

    def columns(self, evidence: np.ndarray) -> np.ndarray:
        """The model's features out of the full evidence table; NaN (a map it lacks) is refused."""
        x = np.asarray(evidence, float)[:, [FEATURES.index(f) for f in self.features]]
        if not np.isfinite(x).all():
            missing = [f for f, ok in zip(self.features, np.isfinite(x).all(axis=0)) if not ok]
            raise ValueError(
                f"edge evidence lacks {', '.join(missing)} (the confidence needs the FPN's maps, with the surface)"
            )
        return x

    @property
    def needs_surface(self) -> bool:
        return any("surface" in f for f in self.features)

    def to_dict(self) -> dict:
        """Plain numbers and strings, for a weights bundle."""
        return {
            "version": VERSION,
            "features": list(self.features),
            "learning_rate": float(self.learning_rate),
            "tree_starts": self.tree_starts.astype(int).tolist(),
            "feature": self.feature.astype(int).tolist(),
            "threshold": self.threshold.astype(float).tolist(),
            "left": self.left.astype(int).tolist(),
            "right": self.right.astype(int).tolist(),
            "value": self.value.astype(float).tolist(),
            "iso_x": self.iso_x.astype(float).tolist(),
            "iso_y": self.iso_y.astype(float).tolist(),
            "provenance": self.provenance,
        }

    @classmethod
    def from_dict(cls, data, source: str | Path = "<bundle>") -> "EdgeConfidence":
        """Checked: a damaged table (unknown feature, a child that points back up, NaN) is an
        InputError naming ``source``, never a wrong or endless computation."""

        def bad(problem: str) -> InputError:
            return InputError(source, f"damaged weights file: confidence {problem}")

        if not isinstance(data, dict) or data.get("version") != VERSION:
            raise bad(f"is not a version-{VERSION} table")
        try:
            features = tuple(str(f) for f in data["features"])
            arrays = {
                k: np.asarray(data[k], float)
                for k in ("tree_starts", "feature", "threshold", "left", "right", "value", "iso_x", "iso_y")
            }
            rate = float(data["learning_rate"])
        except (KeyError, TypeError, ValueError) as exc:
            raise bad(f"table is incomplete or not numbers ({type(exc).__name__})") from exc
        unknown = [f for f in features if f not in FEATURES]
        if unknown or not features:
            raise bad(f"names unknown features {unknown}")
        if not all(np.isfinite(a).all() and a.ndim == 1 for a in arrays.values()) or not math.isfinite(rate):
            raise bad("holds a value that is not a finite number")
        if not 0 < rate <= MAX_LEARNING_RATE:
            raise bad(f"learning rate {rate:g} is outside (0, {MAX_LEARNING_RATE:g}]")
        if (np.abs(arrays["value"]) > MAX_LEAF).any():
            raise bad(f"holds a leaf value beyond +-{MAX_LEAF:g} log-odds")
        n = len(arrays["feature"])
        if n > MAX_NODES or any(len(arrays[k]) != n for k in ("threshold", "left", "right", "value")):
            raise bad("tree arrays differ in length")
        starts = arrays["tree_starts"].astype(np.int64)
        if len(starts) < 2 or starts[0] != 0 or starts[-1] != n or (np.diff(starts) < 1).any():
            raise bad("tree offsets do not cover the nodes")
        left, right, feature = (arrays[k].astype(np.int64) for k in ("left", "right", "feature"))
        size = np.repeat(np.diff(starts), np.diff(starts))
        local = np.arange(n) - np.repeat(starts[:-1], np.diff(starts))
        split = left >= 0
        # children lie after their parent within the tree: every walk down ends
        if (
            (split & ((left <= local) | (right <= local) | (left >= size) | (right >= size))).any()
            or (split & ((feature < 0) | (feature >= len(features)))).any()
            or ((~split) & (right >= 0)).any()
        ):
            raise bad("trees are not well formed")
        iso_x, iso_y = arrays["iso_x"], arrays["iso_y"]
        if (
            len(iso_x) < 2
            or len(iso_x) != len(iso_y)
            or (np.diff(iso_x) < 0).any()
            or (iso_y < 0).any()
            or (iso_y > 1).any()
        ):
            raise bad("isotonic map is not increasing breakpoints to probabilities")
        if (np.diff(iso_y) < 0).any():  # a decreasing map would rank the surest edges as the most doubtful
            raise bad("isotonic map decreases (a higher raw score must never mean a lower probability)")
        provenance = data.get("provenance") if isinstance(data.get("provenance"), dict) else {}
        return cls(
            features,
            rate,
            starts,
            feature,
            arrays["threshold"],
            left,
            right,
            arrays["value"],
            arrays["iso_x"],
            arrays["iso_y"],
            provenance,
        )


def fit_edge_confidence(
    evidence: np.ndarray,
    positive: np.ndarray,
    groups: np.ndarray,
    features: tuple[str, ...] = FEATURES,
    n_trees: int = 200,
    depth: int = 2,
    learning_rate: float = 0.05,
    folds: int = 5,
    seed: int = 0,
    provenance: dict | None = None,
    tree_positive: np.ndarray | None = None,
) -> EdgeConfidence:
    """Fit trees on all edges and the isotonic map on out-of-fold raw outputs, with the groups
    (cities) held out together so that calibration sees edges of cities the trees never saw.
    The isotonic map always targets ``positive``; the trees target ``tree_positive`` when given
    (e.g. edges mostly on the ground truth: ranking by that ordered the Ottawa crops' edges
    better, docs/confidence.md)."""
    try:
        from sklearn.ensemble import GradientBoostingClassifier
        from sklearn.isotonic import IsotonicRegression
        from sklearn.model_selection import GroupKFold
    except ImportError as exc:  # pragma: no cover - the test extra installs it
        raise InputError("fit-confidence", "needs scikit-learn: pip install 'csboundary[fit]'") from exc
    x = np.asarray(evidence, float)[:, [FEATURES.index(f) for f in features]]
    y = np.asarray(positive, bool).astype(int)
    target = y if tree_positive is None else np.asarray(tree_positive, bool).astype(int)
    groups = np.asarray(groups)

    def trees() -> GradientBoostingClassifier:
        return GradientBoostingClassifier(
            n_estimators=n_trees,
            max_depth=depth,
            learning_rate=learning_rate,
            subsample=0.8,
            init="zero",
            random_state=seed,
        )

    out_of_fold = np.zeros(len(y))
    for train, test in GroupKFold(n_splits=min(folds, len(np.unique(groups)))).split(x, y, groups):
        out_of_fold[test] = trees().fit(x[train], target[train]).decision_function(x[test])
    iso = IsotonicRegression(y_min=0.0, y_max=1.0, out_of_bounds="clip").fit(out_of_fold, y)
    model = trees().fit(x, target)
    return from_sklearn(
        model,
        features,
        iso.X_thresholds_,
        iso.y_thresholds_,
        dict(
            provenance or {},
            edges=int(len(y)),
            share_true=float(y.mean()),
            n_trees=n_trees,
            depth=depth,
            learning_rate=learning_rate,
            seed=seed,
            folds=folds,
        ),
    )


def from_sklearn(model, features: tuple[str, ...], iso_x, iso_y, provenance: dict | None = None) -> EdgeConfidence:
    """A fitted ``GradientBoostingClassifier`` (``init='zero'``, two classes) as arrays."""
    starts, parts = [0], {k: [] for k in ("feature", "threshold", "left", "right", "value")}
    for (estimator,) in model.estimators_:
        tree = estimator.tree_
        parts["feature"].append(np.where(tree.children_left >= 0, tree.feature, -1))
        parts["threshold"].append(tree.threshold)
        parts["left"].append(tree.children_left)
        parts["right"].append(tree.children_right)
        parts["value"].append(tree.value[:, 0, 0])
        starts.append(starts[-1] + tree.node_count)
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    return EdgeConfidence(
        tuple(features),
        float(model.learning_rate),
        np.array(starts),
        cat["feature"].astype(np.int64),
        cat["threshold"].astype(float),
        cat["left"].astype(np.int64),
        cat["right"].astype(np.int64),
        cat["value"].astype(float),
        np.asarray(iso_x, float),
        np.asarray(iso_y, float),
        provenance or {},
    )
