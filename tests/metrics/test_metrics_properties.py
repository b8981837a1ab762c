"""Properties of every metric (hypothesis): translation invariance and the [0, 1] range."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from csboundary.graph import BoundaryGraph
from csboundary.metrics import evaluate_city

coord = st.integers(0, 400)
polyline = st.lists(st.tuples(coord, coord), min_size=2, max_size=6)
graph_lines = st.lists(polyline, min_size=0, max_size=4)


def build(polylines, offset=(0, 0)) -> BoundaryGraph:
    return BoundaryGraph.from_polylines([np.asarray(p, dtype=float) + offset for p in polylines])


def jitter(polylines, shifts):
    """The ground truth moved a little, polyline by polyline (a plausible prediction)."""
    return [[(x + dx, y + dy) for x, y in p] for p, (dx, dy) in zip(polylines, shifts)]


@st.composite
def pair(draw):
    gt = draw(graph_lines)
    if draw(st.booleans()):
        pred = jitter(
            gt, draw(st.lists(st.tuples(st.integers(-6, 6), st.integers(-6, 6)), min_size=len(gt), max_size=len(gt)))
        )
        pred = pred[: draw(st.integers(0, len(pred)))] + draw(st.lists(polyline, max_size=2))
    else:
        pred = draw(graph_lines)
    return pred, gt


def same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-9


SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(
    pair(),
    st.tuples(st.integers(-100_000, 100_000), st.integers(-100_000, 100_000)),
    st.sampled_from(["paper", "symmetric"]),
    st.integers(0, 3),
)
def test_translating_both_graphs_changes_no_metric(graphs, offset, variant, seed):
    pred, gt = graphs
    here = evaluate_city(build(pred), build(gt), apls=variant, seed=seed)["metrics"]
    there = evaluate_city(build(pred, offset), build(gt, offset), apls=variant, seed=seed)["metrics"]
    assert here.keys() == there.keys()
    assert all(same(here[k], there[k]) for k in here), {
        k: (here[k], there[k]) for k in here if not same(here[k], there[k])
    }


@SETTINGS
@given(pair(), st.sampled_from(["paper", "symmetric"]), st.integers(0, 3))
def test_every_metric_stays_in_unit_interval(graphs, variant, seed):
    pred, gt = graphs
    metrics = evaluate_city(build(pred), build(gt), apls=variant, seed=seed)["metrics"]
    for name, value in metrics.items():
        assert math.isnan(value) or 0.0 <= value <= 1.0, (name, value)
    shares = [metrics[k] for k in ("tlts", "tlts_too_long", "tlts_too_short", "tlts_infeasible")]
    assert all(math.isnan(s) for s in shares) or abs(sum(shares) - 1) < 1e-9
