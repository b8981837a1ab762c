"""Edges the boundary map supports: hand-computed means along segments, length and support filters."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from csboundary.graph.edge_support import EdgeSupportConfig, longest_gap, segment_support, unsupported_pairs, widened
from csboundary.graph.settings import GraphOverrides
from helpers import bundle_without, shipped_parts


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


def test_longest_gap_counts_the_longest_run_below_the_level():
    m = line_map()
    m[10, 20:27] = 0.0  # a 7 px hole in the line (a parked car)
    m[10, 40:43] = 0.1  # and a 3 px dim stretch
    # along row 10 from x = 0.5 to 59.5: 60 samples, one per column
    assert longest_gap(m, [[0.5, 10.5]], [[59.5, 10.5]], 0.3)[0] == 7
    assert longest_gap(m, [[0.5, 10.5]], [[59.5, 10.5]], 0.05)[0] == 7  # the 0.1 stretch is above 0.05
    assert longest_gap(m, [[30.5, 10.5]], [[59.5, 10.5]], 0.3)[0] == 3
    # across the line (x = 5.5, y 0.5 -> 40.5): 10 samples above it, 30 below
    assert longest_gap(m, [[5.5, 0.5]], [[5.5, 40.5]], 0.3)[0] == 30


def test_gaps_do_not_run_on_from_one_segment_into_the_next():
    m = line_map()
    starts = [[50.5, 30.5], [0.5, 10.5], [0.5, 30.5]]
    ends = [[59.5, 30.5], [59.5, 10.5], [4.5, 30.5]]  # off the line (10 samples), on it, off it (5)
    assert longest_gap(m, starts, ends, 0.5).tolist() == [10, 0, 5]


@settings(max_examples=50, deadline=None)
@given(st.floats(0, 49), st.floats(0, 49), st.floats(0, 49), st.floats(0, 49), st.floats(0.01, 1))
@example(40.99999999999999, 0.0, 0.0, 1e-06, 0.25)  # a length of 41 to within an ulp
def test_on_a_constant_map_the_gap_is_all_or_nothing(x0, y0, x1, y1, value):
    m = np.full((50, 50), value, np.float32)
    # a sample every pixel and both ends; a length within an ulp of a whole number may round either way
    length = np.hypot(x1 - x0, y1 - y0)
    samples = {max(2, int(np.ceil(length + e)) + 1) for e in (-1e-9, 1e-9)}
    assert longest_gap(m, [[x0, y0]], [[x1, y1]], 0.5)[0] in (samples if value < 0.5 else {0})


def test_unsupported_pairs_drops_gapped_edges_whose_mean_passes():
    m = line_map()
    m[10, 15:45] = 0.0  # a 30 px gap in the middle of a 60 px line: mean 0.5
    vertices = np.array([[0.5, 10.5], [59.5, 10.5]])
    probs = np.array([[0.0, 0.9], [0.9, 0.0]])
    assert len(unsupported_pairs(vertices, probs, m, 0.5, EdgeSupportConfig(min_support=0.4, radius_px=0))) == 0
    gap = EdgeSupportConfig(min_support=0.4, radius_px=0, max_gap_px=20)
    assert unsupported_pairs(vertices, probs, m, 0.5, gap).tolist() == [[0, 1]]


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
    from csboundary.pipeline.prediction.patch import PatchPredictor

    predictor = PatchPredictor.load(shipped_weights(), torch.device("cpu"))
    rng = np.random.default_rng(0)
    image = (rng.random((4, 256, 256)) * 255).astype(np.uint8)
    maps = np.zeros((2, 256, 256), np.float32)
    maps[0, 40:44, 20:240:30] = 1.0  # isolated keypoints along a row
    maps[0, 200:204, 20:240:30] = 1.0  # and along another row, 160 px below
    maps[1, 41:43, :] = 1.0  # only the first row is a boundary
    found = predictor.extract(maps)
    predictor.settings = dataclasses.replace(predictor.settings, edge_threshold=0.0)  # every pair is a candidate
    predictor.settings = dataclasses.replace(predictor.settings, support=EdgeSupportConfig(min_support=0.5))
    graph = predictor.connect(None, image, maps, found)
    normal = [(u, v) for (u, v), kind in zip(graph.edges, graph.edge_kinds) if kind == "normal"]
    assert normal  # the row on the boundary keeps its edges
    assert all(graph.vertices[u][1] < 50 and graph.vertices[v][1] < 50 for u, v in normal)


def test_bundle_carries_the_gap_check_and_a_command_line_value_overrides_it(tmp_path):
    import torch

    from csboundary.graph.settings import GraphSettings
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor

    shipped_parts(tmp_path)
    make_bundle(
        tmp_path / "fpn.pt",
        tmp_path / "afanet.pt",
        tmp_path / "b.pt",
        GraphSettings().replaced(min_edge_support=0.2, max_edge_gap=50, edge_gap_level=0.4),
    )
    support = PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu")).settings.support
    assert (support.min_support, support.max_gap_px, support.gap_level) == (0.2, 50, 0.4)
    assert (
        load_predictor(
            tmp_path / "b.pt", "cpu", GraphOverrides(max_edge_gap=0), engine="torch"
        ).settings.support.max_gap_px
        == 0
    )
    # a bundle from before the check (no such settings) loads with the check off
    bundle_without(tmp_path / "b.pt", tmp_path / "older.pt", ("max_edge_gap", "edge_gap_level"))
    assert PatchPredictor.load(tmp_path / "older.pt", torch.device("cpu")).settings.support.max_gap_px == 0
