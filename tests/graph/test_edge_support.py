"""Edges the boundary map supports: hand-computed means along segments, length and support filters."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph.edge_support import EdgeSupportConfig, segment_support, unsupported_pairs, widened


def line_map() -> np.ndarray:
    m = np.zeros((50, 60), np.float32)
    m[10, :] = 1.0  # a boundary along row 10 (y in [10, 11))
    return m


def test_segment_along_the_line_is_fully_supported():
    assert segment_support(line_map(), [[0.5, 10.5]], [[59.5, 10.5]])[0] == pytest.approx(1.0)


def test_segment_across_the_line_touches_it_once():
    # x = 5.5, y from 0.5 to 40.5: 41 samples one pixel apart, one of them on row 10
    assert segment_support(line_map(), [[5.5, 0.5]], [[5.5, 40.5]])[0] == pytest.approx(1 / 41)


def test_samples_outside_the_map_count_as_no_support():
    m = np.ones((10, 10), np.float32)
    # from x = 5.5 to x = 14.5: 10 samples, 5 inside
    assert segment_support(m, [[5.5, 5.5]], [[14.5, 5.5]])[0] == pytest.approx(0.5)


def test_widening_tolerates_a_chord_off_the_line():
    off = [[0.5, 12.5]], [[59.5, 12.5]]  # 2 px below the line
    assert segment_support(line_map(), *off)[0] == 0
    assert segment_support(widened(line_map(), 2), *off)[0] == pytest.approx(1.0)


@settings(max_examples=50, deadline=None)
@given(st.floats(0, 49), st.floats(0, 49), st.floats(0, 49), st.floats(0, 49), st.floats(0, 1))
def test_support_is_the_map_value_on_a_constant_map(x0, y0, x1, y1, value):
    m = np.full((50, 50), value, np.float32)
    assert segment_support(m, [[x0, y0]], [[x1, y1]])[0] == pytest.approx(value, abs=1e-6)


def test_unsupported_pairs_drops_long_and_unbacked_edges_only():
    vertices = np.array([[5.5, 10.5], [25.5, 10.5], [25.5, 40.5], [58.5, 10.5]])
    probs = np.zeros((4, 4))
    probs[0, 1] = probs[1, 2] = probs[0, 3] = 0.9  # along the line / across a block / long along the line
    probs[2, 3] = 0.1  # under threshold: never reported
    config = EdgeSupportConfig(min_support=0.5, max_length_px=40.0)
    bad = {tuple(p) for p in unsupported_pairs(vertices, probs, line_map(), 0.5, config)}
    assert bad == {(1, 2), (0, 3)}
    assert len(unsupported_pairs(vertices, probs, line_map(), 0.5, EdgeSupportConfig())) == 0


def test_predictor_applies_the_check(tmp_path):
    """A predictor with the check on never returns an AfANet edge the map does not back."""
    import torch

    from csboundary.models.checkpoint import shipped_weights
    from csboundary.pipeline.patch import PatchPredictor

    predictor = PatchPredictor.load(shipped_weights(), torch.device("cpu"))
    rng = np.random.default_rng(0)
    image = (rng.random((4, 256, 256)) * 255).astype(np.uint8)
    maps = np.zeros((2, 256, 256), np.float32)
    maps[0, 40:44, 20:240:30] = 1.0  # isolated keypoints along a row
    maps[0, 200:204, 20:240:30] = 1.0  # and along another row, 160 px below
    maps[1, 41:43, :] = 1.0  # only the first row is a boundary
    found = predictor.extract(maps)
    predictor.edge_threshold = 0.0  # every pair is a candidate
    predictor.support = EdgeSupportConfig(min_support=0.5)
    graph = predictor.connect(None, image, maps, found)
    normal = [(u, v) for (u, v), kind in zip(graph.edges, graph.edge_kinds) if kind == "normal"]
    assert normal  # the row on the boundary keeps its edges
    assert all(graph.vertices[u][1] < 50 and graph.vertices[v][1] < 50 for u, v in normal)
