"""Vertex extraction from keypoint maps (paper IV-C), checked on hand-drawn heat and real labels."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import box

from csboundary.data.synth.streets import round_convex_corners
from csboundary.data.windows import PixelWindow
from csboundary.graph import BoundaryGraph
from csboundary.graph.vertex_extraction import VertexConfig, extract_vertices, extract_vertices_with_scores
from csboundary.labels.boundaries import Boundary
from csboundary.labels.config import LabelConfig
from csboundary.labels.keypoints import compute_keypoints
from csboundary.labels.rasterize import keypoint_heat
from csboundary.labels.select import boundary_bounds

SIGMA = 3.0


def centres(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (x, y) of every pixel centre: pixel [r, c] is at (c + 0.5, r + 0.5)."""
    rows, cols = np.mgrid[0:h, 0:w]
    return cols + 0.5, rows + 0.5


def heat(distance: np.ndarray, amplitude: float = 1.0) -> np.ndarray:
    return amplitude * np.exp(-(distance**2) / (2 * SIGMA**2))


def blob(h: int, w: int, x: float, y: float, amplitude: float = 1.0) -> np.ndarray:
    px, py = centres(h, w)
    return heat(np.hypot(px - x, py - y), amplitude)


def arc_distance(px, py, cx, cy, radius, a0, a1):
    """Distance from points to the circle arc of ``radius`` about (cx, cy) from angle a0 to a1 (< 2 pi apart)."""
    angle = np.arctan2(py - cy, px - cx)
    on_arc = ((angle - a0) % (2 * math.pi)) <= (a1 - a0)
    to_circle = np.abs(np.hypot(px - cx, py - cy) - radius)
    ends = [(cx + radius * math.cos(a), cy + radius * math.sin(a)) for a in (a0, a1)]
    to_ends = np.minimum(*[np.hypot(px - ex, py - ey) for ex, ey in ends])
    return np.where(on_arc, to_circle, to_ends)


def segment_distance(px, py, p, q):
    p, q = np.asarray(p, float), np.asarray(q, float)
    d = q - p
    t = np.clip(((px - p[0]) * d[0] + (py - p[1]) * d[1]) / (d @ d), 0.0, 1.0)
    return np.hypot(px - (p[0] + t * d[0]), py - (p[1] + t * d[1]))


# -- isolated keypoints -------------------------------------------------------------------------


def test_gaussian_blob_gives_one_vertex_at_its_centre():
    prob = blob(60, 70, 40.3, 27.8)
    graph, scores = extract_vertices_with_scores(prob)
    assert isinstance(graph, BoundaryGraph)
    assert graph.n_vertices == 1 and graph.n_edges == 0
    assert math.dist(graph.vertices[0], (40.3, 27.8)) < 1.0
    assert math.dist(graph.vertices[0], (40.3, 27.8)) < 0.25  # the weighted centroid is sub-pixel
    assert graph.vertex_kinds == ["isolated"]
    assert scores.shape == (1,) and scores[0] == pytest.approx(prob.max())


def test_pixel_convention_single_pixel_and_one_by_one_maps():
    prob = np.zeros((5, 7))
    prob[2, 3] = 1.0  # pixel [2, 3] is centred at (3.5, 2.5)
    graph = extract_vertices(prob, VertexConfig(min_area_px=1))
    assert graph.vertices.tolist() == [[3.5, 2.5]] and graph.n_edges == 0
    assert extract_vertices(prob).n_vertices == 0  # below min_area_px=4: noise
    one = extract_vertices(np.ones((1, 1)), VertexConfig(min_area_px=1))
    assert one.vertices.tolist() == [[0.5, 0.5]]
    assert extract_vertices(np.ones((1, 1))).n_vertices == 0
    assert extract_vertices(np.zeros((0, 4))).n_vertices == 0


def test_separate_blobs_give_one_vertex_each():
    truth = [(12.2, 10.7), (50.5, 14.0), (30.0, 40.9), (70.8, 45.3), (8.6, 52.1)]
    prob = np.maximum.reduce([blob(64, 84, x, y, a) for (x, y), a in zip(truth, (1.0, 0.9, 0.8, 0.7, 0.6))])
    graph, scores = extract_vertices_with_scores(prob)
    assert graph.n_vertices == len(truth) and graph.n_edges == 0
    for x, y in truth:
        assert np.min(np.hypot(graph.vertices[:, 0] - x, graph.vertices[:, 1] - y)) < 1.0
    assert sorted(scores.round(1).tolist()) == [0.6, 0.7, 0.8, 0.9, 1.0]


def test_empty_map_gives_an_empty_graph():
    for prob in (np.zeros((30, 40)), np.full((30, 40), 0.49)):
        graph, scores = extract_vertices_with_scores(prob)
        assert graph.n_vertices == 0 and graph.n_edges == 0 and scores.shape == (0,)
        assert graph.to_dict()["vertices"] == [] and graph.to_dict()["edges"] == []


def test_small_noise_is_dropped_and_threshold_is_configurable():
    prob = blob(40, 40, 20.0, 20.0, amplitude=0.45)
    prob[3, 3] = prob[3, 4] = 0.9  # 2 px of noise
    assert extract_vertices(prob).n_vertices == 0
    assert extract_vertices(prob, VertexConfig(threshold=0.3)).n_vertices == 1
    assert extract_vertices(prob, VertexConfig(threshold=0.3, min_area_px=1)).n_vertices == 2


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_values_raise(bad):
    prob = blob(20, 20, 10.0, 10.0)
    prob[4, 5] = bad
    with pytest.raises(ValueError, match="NaN" if bad != bad else "infinite"):
        extract_vertices(prob)


def test_bad_shapes_and_configs_raise():
    with pytest.raises(ValueError, match="2-D"):
        extract_vertices(np.zeros((2, 3, 4)))
    with pytest.raises(ValueError):
        VertexConfig(min_area_px=0)
    with pytest.raises(ValueError):
        VertexConfig(threshold=float("nan"))


@settings(max_examples=60, deadline=None)
@given(
    h=st.integers(10, 60),
    w=st.integers(10, 60),
    fx=st.floats(0.0, 1.0),
    fy=st.floats(0.0, 1.0),
    amplitude=st.floats(0.7, 1.0),
)
def test_blob_anywhere_gives_its_centre(h, w, fx, fy, amplitude):
    # The thresholded disc (radius sigma * sqrt(2 ln(2 a)) <= 3.54 px) lies wholly inside the map.
    x, y = 4.0 + fx * (w - 8.0), 4.0 + fy * (h - 8.0)
    graph = extract_vertices(blob(h, w, x, y, amplitude))
    assert graph.n_vertices == 1 and graph.n_edges == 0
    assert math.dist(graph.vertices[0], (x, y)) < 1.0


# -- gathered runs ------------------------------------------------------------------------------


def test_curved_band_gives_its_two_ends_and_a_corner_edge_along_the_arc():
    cx, cy, radius = 20.0, 15.0, 40.0
    px, py = centres(80, 80)
    prob = heat(arc_distance(px, py, cx, cy, radius, 0.0, math.pi / 2))  # from (60, 15) to (20, 55)
    graph = extract_vertices(prob)
    assert graph.n_vertices == 2 and graph.n_edges == 1
    assert graph.vertex_kinds == ["corner", "corner"] and graph.edge_kinds == ["corner"]
    ends = [(cx + radius, cy), (cx, cy + radius)]
    for end in ends:
        assert min(math.dist(v, end) for v in graph.vertices) < 3.0
    line = graph.edge_polyline(0)
    assert np.array_equal(line[0], graph.vertices[graph.edges[0, 0]]) and np.array_equal(
        line[-1], graph.vertices[graph.edges[0, 1]]
    )
    assert np.all(arc_distance(line[:, 0], line[:, 1], cx, cy, radius, 0.0, math.pi / 2) < 2.0)
    assert graph.edge_lengths()[0] == pytest.approx(math.pi / 2 * radius, rel=0.10)
    assert np.all(np.linalg.norm(np.diff(line, axis=0), axis=1) <= math.sqrt(2) + 1e-9)  # 8-connected steps
    assert 0.5 < graph.edge_scores[0] <= 1.0
    again = BoundaryGraph.from_dict(graph.to_dict())  # the corner polyline survives the JSON format
    assert again.edge_kinds == ["corner"] and np.allclose(again.edge_polyline(0), line)


def test_length_rule_separates_isolated_from_gathered():
    px, py = centres(40, 60)
    short = heat(segment_distance(px, py, (20.0, 20.0), (24.0, 20.0)))  # 4 px: one keypoint
    long_ = heat(segment_distance(px, py, (15.0, 20.0), (45.0, 20.0)))  # 30 px: a run
    g_short, g_long = extract_vertices(short), extract_vertices(long_)
    assert g_short.n_vertices == 1 and g_short.n_edges == 0
    assert math.dist(g_short.vertices[0], (22.0, 20.0)) < 1.0
    assert g_long.n_vertices == 2 and g_long.n_edges == 1
    assert extract_vertices(long_, VertexConfig(gather_min_length_px=100.0)).n_vertices == 1


def test_rounded_square_label_map_gives_four_corner_edges_at_the_run_ends():
    lo, hi, radius = 130.0, 330.0, 30.0  # away from every 1000 px grid and margin line
    b = [Boundary(np.asarray(round_convex_corners(box(lo, lo, hi, hi), radius)[0].exterior.coords), True)]
    kps = compute_keypoints(b, LabelConfig(aux_spacing_px=0))
    assert len(kps[0].runs) == 4
    window = PixelWindow(100, 100, 260, 260)
    prob = keypoint_heat(kps, boundary_bounds(b), window, sigma=SIGMA)
    graph = extract_vertices(prob)
    origin = np.array([window.col_off, window.row_off], float)
    runs = [kps[0].boundary.at(np.array(run)) - origin for run in kps[0].runs]  # each (2, 2) in window pixels
    assert graph.n_edges == 4 and graph.edge_kinds == ["corner"] * 4 and graph.n_vertices == 8
    matched = set()
    for u, v in graph.edges:  # both ends of every corner edge sit on the two ends of one run
        pu, pv = graph.vertices[u], graph.vertices[v]
        errors = [
            min(max(math.dist(pu, a), math.dist(pv, e)), max(math.dist(pu, e), math.dist(pv, a))) for a, e in runs
        ]
        best = int(np.argmin(errors))
        assert errors[best] < 3.0
        matched.add(best)
    assert matched == {0, 1, 2, 3}
    for length in graph.edge_lengths():  # each edge follows a quarter circle
        assert length == pytest.approx(math.pi / 2 * radius, rel=0.10)


def test_branched_band_uses_its_longest_path():
    centre = np.array([50.0, 50.0])
    tips = [
        centre + r * np.array([math.cos(a), math.sin(a)])
        for r, a in ((30, -math.pi / 2), (22, math.pi / 6), (14, 5 * math.pi / 6))
    ]
    px, py = centres(100, 100)
    prob = heat(np.minimum.reduce([segment_distance(px, py, centre, t) for t in tips]))
    graph = extract_vertices(prob)
    assert graph.n_vertices == 2 and graph.n_edges == 1 and graph.edge_kinds == ["corner"]
    for tip in tips[:2]:  # the two longest arms
        assert min(math.dist(v, tip) for v in graph.vertices) < 3.0


def test_ring_band_does_not_crash_and_gives_two_ends():
    px, py = centres(70, 70)
    prob = heat(np.abs(np.hypot(px - 35.0, py - 35.0) - 20.0))
    graph, scores = extract_vertices_with_scores(prob)
    assert graph.n_vertices == 2 and graph.n_edges == 1 and graph.edge_kinds == ["corner"]
    assert len(scores) == 2
    assert math.dist(*graph.vertices) > 30.0  # nearly opposite points of the ring
    assert graph.edge_lengths()[0] == pytest.approx(math.pi * 20.0, rel=0.15)  # about half of it


def test_large_map_with_many_pieces_finds_every_piece():
    """(Speed is measured in benchmarks/vertex_extraction_speed.py, not here.)"""
    seeds = np.full((1100, 1100), 255, np.uint8)  # 0 where heat is 1, as keypoint_heat seeds it
    cells = [(35 + 70 * i, 35 + 70 * j) for j in range(16) for i in range(16)][:150]  # 70 px apart
    n_blobs = 100
    for k, (x, y) in enumerate(cells):
        if k < n_blobs:
            seeds[y, x] = 0
        else:  # a quarter circle of radius 25 px: a gathered run
            cv2.ellipse(seeds, (x - 12, y - 12), (25, 25), 0, 0, 90, 0, 1)
    distance = cv2.distanceTransform(seeds, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    prob = np.exp(-(distance**2) / (2 * SIGMA**2)).astype(np.float32)
    graph = extract_vertices(prob)
    assert graph.vertex_kinds.count("isolated") == n_blobs
    assert graph.n_edges == len(cells) - n_blobs and graph.n_vertices == n_blobs + 2 * graph.n_edges
