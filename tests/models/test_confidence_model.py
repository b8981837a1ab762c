"""The edge confidence model: its arrays compute what scikit-learn's trees compute, it survives a
weights bundle as plain numbers, a damaged table is refused, and it is calibrated where it was fitted."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.errors import InputError
from csboundary.graph.edge_evidence import FEATURES
from csboundary.metrics.confidence_quality import expected_calibration_error, roc_auc
from csboundary.models.confidence_model import EdgeConfidence, fit_edge_confidence

sklearn = pytest.importorskip("sklearn")


def noisy_edges(n: int = 1200, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Evidence where truth depends on the boundary map's mean and the surface contrast."""
    rng = np.random.default_rng(seed)
    evidence = rng.uniform(0, 1, (n, len(FEATURES)))
    logit = 6 * (evidence[:, FEATURES.index("boundary_mean")] - 0.5) + 3 * (
        evidence[:, FEATURES.index("surface_contrast")] - 0.5
    )
    positive = rng.uniform(0, 1, n) < 1 / (1 + np.exp(-logit))
    return evidence, positive, np.arange(n) % 6


@pytest.fixture(scope="module")
def fitted() -> EdgeConfidence:
    evidence, positive, groups = noisy_edges()
    return fit_edge_confidence(evidence, positive, groups, n_trees=40, depth=2)


def test_the_arrays_compute_what_the_fitted_trees_compute():
    from sklearn.ensemble import GradientBoostingClassifier

    from csboundary.models.confidence_model import from_sklearn

    evidence, positive, _ = noisy_edges()
    model = GradientBoostingClassifier(n_estimators=15, max_depth=3, init="zero", random_state=0).fit(
        evidence, positive
    )
    arrays = from_sklearn(model, FEATURES, [0.0, 1.0], [0.0, 1.0])
    np.testing.assert_allclose(arrays.raw(evidence), model.decision_function(evidence), atol=1e-9)


def test_it_orders_and_calibrates_fresh_edges(fitted):
    evidence, positive, _ = noisy_edges(seed=1)
    p = fitted.probability(evidence)
    assert ((p >= 0) & (p <= 1)).all()
    assert roc_auc(p, positive) > 0.8
    assert expected_calibration_error(p, positive) < 0.06


def test_plain_numbers_round_trip(fitted):
    import torch

    data = fitted.to_dict()
    assert all(not isinstance(v, np.ndarray) for v in data.values())
    buffer = __import__("io").BytesIO()
    torch.save({"confidence": data}, buffer)
    buffer.seek(0)
    back = EdgeConfidence.from_dict(torch.load(buffer, weights_only=True)["confidence"])
    evidence, _, _ = noisy_edges(seed=2)
    np.testing.assert_array_equal(back.probability(evidence), fitted.probability(evidence))


@pytest.mark.parametrize(
    "damage, problem",
    [
        (lambda d: d.update(version=99), "version"),
        (lambda d: d.update(features=["no_such_feature"] + d["features"][1:]), "unknown features"),
        (lambda d: d["left"].__setitem__(0, 0), "not well formed"),  # the root's left child is itself: an endless walk
        (lambda d: d["threshold"].__setitem__(0, float("nan")), "finite"),
        (lambda d: d.update(iso_y=[2.0] * len(d["iso_y"])), "isotonic"),
        (lambda d: d.pop("value"), "incomplete"),
    ],
)
def test_a_damaged_table_is_refused(fitted, damage, problem):
    data = fitted.to_dict()
    damage(data)
    with pytest.raises(InputError, match=problem):
        EdgeConfidence.from_dict(data, "w.pt")


def test_evidence_without_the_maps_it_needs_is_refused(fitted):
    evidence, _, _ = noisy_edges(n=5)
    evidence[:, FEATURES.index("surface_contrast")] = np.nan
    with pytest.raises(ValueError, match="surface_contrast"):
        fitted.probability(evidence)
