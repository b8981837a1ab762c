"""Labels from vector ground truth: keypoints, maps, patch graphs and adjacency, checked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import box

from csboundary.data.grid import PatchGrid
from csboundary.data.synth.streets import round_convex_corners
from csboundary.data.windows import PixelWindow
from csboundary.labels.adjacency import adjacency_label
from csboundary.labels.boundaries import Boundary, boundaries_from_world
from csboundary.labels.config import LabelConfig
from csboundary.labels.keypoints import INTERSECTION, boundary_keypoints, compute_keypoints, curvature_keypoints
from csboundary.labels.patch_graph import window_graph
from csboundary.labels.rasterize import keypoint_heat, orientation_label, segmentation_label
from csboundary.labels.select import boundary_bounds

NO_AUX = LabelConfig(aux_spacing_px=0)


def ring(polygon) -> Boundary:
    return Boundary(np.asarray(polygon.exterior.coords), True)


@pytest.mark.parametrize("radius", [20.0, 40.0, 79.0])
def test_rounded_square_gives_four_gathered_corners_at_the_tangent_points(radius):
    lo, hi = 130.0, 730.0  # away from every 1000 px grid line
    b = ring(round_convex_corners(box(lo, lo, hi, hi), radius)[0])
    runs, isolated = curvature_keypoints(b, NO_AUX)
    assert len(runs) == 4 and isolated == []
    tangent_points = [
        (lo + radius, lo),
        (hi - radius, lo),
        (hi, lo + radius),
        (hi, hi - radius),
        (hi - radius, hi),
        (lo + radius, hi),
        (lo, hi - radius),
        (lo, lo + radius),
    ]
    ends = b.at(np.array([s for run in runs for s in run]))
    for end in ends:  # every run end lies where an arc meets a straight side
        assert min(math.dist(end, t) for t in tangent_points) < 2.0
    for a, e in runs:  # each run is one quarter circle
        length = (e - a) % b.length
        assert length == pytest.approx(math.pi / 2 * radius, abs=3.0)
    kp = boundary_keypoints(b, NO_AUX)
    straight = [p for p, k in zip(kp.points, kp.kinds) if k != INTERSECTION]
    assert len(straight) == 8  # no curvature keypoint on the straight sides


def test_sharp_corner_gives_exactly_one_isolated_keypoint():
    b = Boundary(np.array([[100.0, 400.0], [400.0, 400.0], [400.0, 120.0]]), False)
    runs, isolated = curvature_keypoints(b, NO_AUX)
    assert runs == [] and len(isolated) == 1
    assert math.dist(b.at([isolated[0]])[0], (400.0, 400.0)) < 1.5


def test_gradual_curve_gets_isolated_keypoints_by_turning():
    # A circle arc of radius 400 px (below the corner rate) turning 90 degrees: 4 keypoints of 20 deg
    # would need 80 deg; 90 deg of turning gives floor(90 / 20) = 4 gradual keypoints.
    t = np.linspace(0, math.pi / 2, 400)
    pts = np.stack([300 + 400 * np.cos(t), 300 + 400 * np.sin(t)], axis=1)
    runs, isolated = curvature_keypoints(Boundary(pts, False), NO_AUX)
    assert runs == [] and len(isolated) == 4


def test_straight_boundary_has_keypoints_on_patch_edges_and_every_aux_line():
    config = LabelConfig()  # core 1000, margin 50, aux 250
    b = Boundary(np.array([[-10.0, 612.3], [2510.0, 612.3]]), False)
    kp = boundary_keypoints(b, config)
    xs = sorted(p[0] for p, k in zip(kp.points, kp.kinds) if k == INTERSECTION)
    expected = sorted(
        {0, 250, 500, 750, 1000, 1250, 1500, 1750, 2000, 2250, 2500, 950, 1050, 1950, 2050, -50 + 1000 * 0, 50}
    )
    expected = [x for x in expected if -10 <= x <= 2510]
    assert xs == pytest.approx(expected, abs=1e-9)
    assert all(p[1] == pytest.approx(612.3) for p in kp.points)
    assert {k for k in kp.kinds} == {INTERSECTION, "end"}


def test_orientation_and_segmentation_by_hand():
    b = [Boundary(np.array([[2.0, 10.5], [18.0, 10.5]]), False)]
    window = PixelWindow(0, 0, 20, 20)
    seg = segmentation_label(b, boundary_bounds(b), window, width=3)
    assert set(np.flatnonzero(seg.any(axis=1))) == {9, 10, 11}  # the line runs through row 10's centre
    vectors, codes = orientation_label(b, boundary_bounds(b), window, width=3)
    assert vectors[:, 10, 10].tolist() == [1.0, 0.0] and codes[10, 10] == 1  # +col: angle 0 -> bin 1
    up = [Boundary(np.array([[10.5, 18.0], [10.5, 2.0]]), False)]  # towards -row: 90 deg -> bin 17
    _, codes_up = orientation_label(up, boundary_bounds(up), window, width=1)
    assert codes_up[10, 10] == 17 and codes_up[0, 0] == 0


def test_keypoint_heat_is_a_gaussian_of_the_distance():
    b = [Boundary(np.array([[0.0, 50.5], [1000.0, 50.5]]), False)]
    kps = compute_keypoints(b, LabelConfig(aux_spacing_px=250, heat_sigma_px=3.0))
    heat = keypoint_heat(kps, boundary_bounds(b), PixelWindow(200, 0, 100, 100), sigma=3.0)
    assert heat[50, 50] == pytest.approx(1.0)  # keypoint at (250, 50.5) -> pixel [50, 250 - 200]
    assert heat[53, 50] == pytest.approx(math.exp(-0.5), rel=1e-3)  # 3 px away: exp(-9 / 18)
    assert heat[50, 10] < 1e-6  # far from every keypoint


@pytest.fixture(scope="module")
def city_labels():
    from csboundary.data.synth.city import plan_city
    from csboundary.data.synth.config import SynthConfig

    city = plan_city(SynthConfig(tile_size=1200, gsd=0.3), "train", 11, (1, 2))  # 2400 x 1200 px
    transform = Affine(0.3, 0, 0, 0, -0.3, city.size_m[1])
    lines = [line for line, _ in city.scene.network.boundaries]
    boundaries = boundaries_from_world(lines, transform)
    config = LabelConfig()
    return (
        boundaries,
        compute_keypoints(boundaries, config),
        boundary_bounds(boundaries),
        PatchGrid(2400, 1200, transform, config.grid),
    )


def test_overlapping_patches_agree_inside_their_overlap(city_labels):
    boundaries, kps, bounds, grid = city_labels
    a, b = grid.patch(0, 0), grid.patch(0, 1)
    overlap = grid.overlap(a, b)
    ga, ids_a = window_graph(kps, bounds, a.expanded)
    gb, ids_b = window_graph(kps, bounds, b.expanded)
    from csboundary.labels.select import inside

    in_a = {ids_a[i] for i in np.flatnonzero(inside(ga.vertices + [a.expanded.col_off, a.expanded.row_off], overlap))}
    in_b = {ids_b[i] for i in np.flatnonzero(inside(gb.vertices + [b.expanded.col_off, b.expanded.row_off], overlap))}
    assert in_a and in_a == in_b
    heat_a = keypoint_heat(kps, bounds, a.expanded)
    heat_b = keypoint_heat(kps, bounds, b.expanded)
    rows_a, cols_a = overlap.relative_to(a.expanded).slices()
    rows_b, cols_b = overlap.relative_to(b.expanded).slices()
    assert np.allclose(
        heat_a[rows_a, cols_a], heat_b[rows_b, cols_b], rtol=0, atol=1e-6
    )  # equal up to float32 rounding
    seg_a = segmentation_label(boundaries, bounds, a.expanded)
    seg_b = segmentation_label(boundaries, bounds, b.expanded)
    assert np.array_equal(seg_a[rows_a, cols_a], seg_b[rows_b, cols_b])


def _matrix(graph) -> np.ndarray:
    m = np.zeros((graph.n_vertices, graph.n_vertices), np.uint8)
    m[graph.edges[:, 0], graph.edges[:, 1]] = 1
    m[graph.edges[:, 1], graph.edges[:, 0]] = 1
    return m


def test_adjacency_of_ground_truth_vertices_is_the_patch_graph(city_labels):
    boundaries, kps, bounds, grid = city_labels
    for patch in grid:
        graph, _ = window_graph(kps, bounds, patch.expanded)
        origin = np.array([patch.expanded.col_off, patch.expanded.row_off])
        label = adjacency_label(graph.vertices + origin, boundaries, bounds, patch.expanded)
        assert graph.n_edges > 10
        assert np.array_equal(label, _matrix(graph))


def test_vertex_far_from_every_boundary_has_no_edges():
    b = [Boundary(np.array([[0.0, 100.0], [1000.0, 100.0]]), False)]
    vertices = np.array([[100.0, 104.0], [300.0, 97.0], [200.0, 130.0], [500.0, 100.0]])  # 3rd is 30 px away
    label = adjacency_label(vertices, b, boundary_bounds(b), PixelWindow(0, 0, 1000, 1000), tolerance=10.0)
    assert label[2].sum() == 0 and label[:, 2].sum() == 0
    assert label[0, 1] == 1 and label[1, 3] == 1 and label[0, 3] == 0  # consecutive along the line only


def test_adjacency_needs_the_boundary_between_to_stay_in_the_window():
    # A U-shaped boundary leaving the window between two of its vertices.
    b = [Boundary(np.array([[10.0, 10.0], [10.0, 200.0], [50.0, 200.0], [50.0, 10.0]]), False)]
    window = PixelWindow(0, 0, 100, 100)
    label = adjacency_label(np.array([[10.0, 50.0], [50.0, 50.0]]), b, boundary_bounds(b), window)
    assert label.sum() == 0


@settings(max_examples=25, deadline=None)
@given(dx=st.integers(-3, 3), dy=st.integers(-3, 3), radius=st.floats(15, 60))
def test_keypoints_move_with_the_boundary_by_whole_grid_periods(dx, dy, radius):
    """Shifting geometry by whole periods of the keypoint lines (1000 px: cores, their +-50 px
    expanded edges and the 250 px auxiliary grid all repeat) shifts every keypoint with it."""
    poly = round_convex_corners(box(30, 40, 420, 230), radius)[0]
    shift = np.array([dx * 1000.0, dy * 1000.0])
    a = boundary_keypoints(ring(poly))
    b = boundary_keypoints(Boundary(np.asarray(poly.exterior.coords) + shift, True))
    assert len(a.s) == len(b.s) and a.kinds == b.kinds
    assert np.allclose(a.points + shift, b.points, atol=1e-6)


def test_label_files_round_trip_and_show(tmp_path):
    from csboundary.data.synth.city import synthesize_city
    from csboundary.data.synth.config import SynthConfig
    from csboundary.graph import BoundaryGraph
    from csboundary.labels.writer import PATCH_DIR, load_patch_arrays

    synthesize_city(tmp_path / "c", 4, "train", (1, 1), SynthConfig(tile_size=1200, gsd=0.3), progress=False)
    from helpers import run_cli as run

    result = run("labels", str(tmp_path / "c"), "--out", str(tmp_path / "lab"), "--quiet")
    assert result.returncode == 0, result.stderr
    arrays = load_patch_arrays(tmp_path / "lab" / PATCH_DIR / "r01_c01.npz")
    assert arrays["segmentation"].shape == (1100, 1100) and arrays["orientation"].shape == (2, 1100, 1100)
    assert (
        arrays["valid"][:250, :250].all() and not arrays["valid"][-1, -1]
    )  # patch (1,1) reaches past the 1200 px mosaic
    graph = BoundaryGraph.read_json(tmp_path / "lab" / PATCH_DIR / "r01_c01.graph.json")
    assert graph.transform is not None and graph.n_vertices > 0
    result = run(
        "show",
        str(tmp_path / "c"),
        "--labels",
        str(tmp_path / "lab"),
        "--patch",
        "1,1",
        "--out",
        str(tmp_path / "l.png"),
    )
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "l.png").stat().st_size > 1000


def test_pixel_chain_ground_truth_gives_the_same_corners_after_import_simplification():
    """Topo-boundary labels are chains of every pixel; after the importer's simplification the
    rounded square still gives four gathered corners and no spurious keypoints."""
    from csboundary.data.topo_boundary import pixels_to_line

    radius = 40.0
    poly = round_convex_corners(box(130, 130, 730, 730), radius)[0]
    dense, _ = __import__("csboundary.graph.polyline", fromlist=["dense_samples"]).dense_samples(
        np.asarray(poly.exterior.coords), 0.25
    )
    pixels = np.floor(dense).astype(int)
    keep = np.concatenate([[True], np.any(np.diff(pixels, axis=0) != 0, axis=1)])
    chain = pixels[keep][:, ::-1]  # [row, col] like dense_seq
    line = pixels_to_line(Affine.identity(), chain)
    runs, isolated = curvature_keypoints(Boundary(np.asarray(line.coords), True), NO_AUX)
    assert len(runs) == 4 and isolated == []


def test_a_round_island_gets_three_vertices_and_its_whole_ring():
    t = np.linspace(0, 2 * np.pi, 200)
    circle = Boundary(np.stack([150 + 50 * np.cos(t), 150 + 50 * np.sin(t)], axis=1), True)
    circle.points[-1] = circle.points[0]
    kps = compute_keypoints([circle], NO_AUX)
    assert len(kps[0].s) >= 3
    graph, _ = window_graph(kps, boundary_bounds([circle]), PixelWindow(-50, -50, 1100, 1100))
    assert graph.n_edges == graph.n_vertices >= 3
    assert graph.edge_lengths().sum() == pytest.approx(circle.length, rel=1e-6)
