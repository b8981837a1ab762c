"""Graph stitching through shared vertices: hand-made patch graphs with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import pdist

from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.graph import BoundaryGraph
from csboundary.graph.stitching import (
    StitchConfig,
    border_distance,
    owner_bounds,
    polyline_midpoint,
    stitch_patch_graphs,
)

# 1 x 2 patches: cores [0, 100) and [100, 200); windows [-10, 110) and [90, 210).
GRID = PatchGrid(200, 100, config=GridConfig(core=100, margin=10))


def graph(points, edges, **extra) -> BoundaryGraph:
    return BoundaryGraph(np.array(points, float), np.array(edges), **extra)


def test_a_shared_vertex_joins_the_two_sides():
    left = graph([[50, 50], [100, 50], [108, 50]], [[0, 1], [1, 2]])  # b-c lies in the right core
    right = graph([[100, 50], [150, 50]], [[0, 1]])
    city = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID)
    assert city.n_vertices == 3 and city.n_edges == 2
    assert sorted(map(tuple, city.vertices.tolist())) == [(50, 50), (100, 50), (150, 50)]
    assert sorted(map(tuple, city.edge_patches.tolist())) == [(0, 0), (0, 1)]
    degree = np.bincount(city.edges.ravel())
    assert sorted(degree.tolist()) == [1, 1, 2]  # one unbroken path


def test_an_edge_both_patches_predict_is_kept_once_from_its_owner():
    both = graph([[95, 20], [105, 30]], [[0, 1]], edge_scores=np.array([0.9]))
    other = graph([[95, 20], [105, 30]], [[0, 1]], edge_scores=np.array([0.4]))
    city = stitch_patch_graphs({(0, 0): both, (0, 1): other}, GRID)
    assert city.n_edges == 1 and city.edge_patches.tolist() == [[0, 1]] and city.edge_scores.tolist() == [0.4]


def test_an_edge_only_the_non_owner_predicts_is_dropped():
    left = graph([[95, 20], [107, 30]], [[0, 1]])  # midpoint x = 101: the right patch decides
    city = stitch_patch_graphs({(0, 0): left, (0, 1): graph([[95, 20], [107, 30]], np.zeros((0, 2)))}, GRID)
    assert city.n_edges == 0


def test_a_vertex_cut_by_the_window_border_snaps_to_the_neighbours_version():
    # The left window ends at x = 110: its vertex at 108.5 comes from a cut blob; the right patch,
    # which sees the whole blob, puts it at 106.
    left = graph([[50, 50], [108.5, 50]], [[0, 1]])
    right = graph([[106, 50], [150, 50]], [[0, 1]])
    city = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID)
    assert city.n_vertices == 3 and sorted(city.vertices[:, 0].tolist()) == [50, 106, 150]
    assert sorted(np.bincount(city.edges.ravel()).tolist()) == [1, 1, 2]
    # Without snapping the two sides stay apart.
    apart = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID, StitchConfig(snap_px=0))
    assert apart.n_vertices == 4


def test_patches_on_the_mosaic_border_keep_edges_beyond_it():
    outer = graph([[-8, 10], [-2, 30]], [[0, 1]])  # in the left patch's margin, outside the mosaic
    city = stitch_patch_graphs({(0, 0): outer, (0, 1): BoundaryGraph()}, GRID)
    assert city.n_edges == 1
    assert owner_bounds(GRID.patch(0, 0), GRID) == (-np.inf, -np.inf, 100, np.inf)


def test_corner_polylines_follow_their_merged_ends():
    arc = np.array([[60.0, 60], [80, 62], [99.6, 80]])
    left = graph(
        [[60, 60], [99.6, 80]], [[0, 1]], edge_kinds=["corner"], edge_polylines=[arc], edge_scores=np.array([0.8])
    )
    right = graph([[100, 80], [150, 80]], [[0, 1]], edge_kinds=["normal"], edge_polylines=[None])
    city = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID)
    assert city.n_vertices == 3  # 99.6 and 100 are within merge_px
    k = city.edge_kinds.index("corner")
    line = city.edge_polyline(k)
    u, v = city.edges[k]
    assert np.array_equal(line[0], city.vertices[u]) and np.array_equal(line[-1], city.vertices[v])


def test_geometry_helpers():
    assert polyline_midpoint(np.array([[0, 0], [10, 0], [10, 30]])).tolist() == [10, 10]
    d = border_distance(np.array([[0.0, 50], [105, 50], [50, 95]]), GRID.patch(0, 0), GRID)
    assert d.tolist() == [110, 5, 60]  # only the right side (x = 110) has a neighbour behind it


points = st.lists(st.tuples(st.floats(-10, 210), st.floats(-10, 110)), min_size=2, max_size=25)


@settings(max_examples=60, deadline=None)
@given(left=points, right=points, data=st.data())
def test_no_two_output_vertices_are_within_the_merge_radius(left, right, data):
    graphs = {}
    for index, pts in (((0, 0), left), ((0, 1), right)):
        n = len(pts)
        edges = data.draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=30))
        edges = [e for e in edges if e[0] != e[1]]
        graphs[index] = graph(pts, np.array(edges).reshape(-1, 2))
    city = stitch_patch_graphs(graphs, GRID)
    if city.n_vertices > 1:
        assert pdist(city.vertices).min() >= StitchConfig().merge_px
    assert len({tuple(sorted(e)) for e in city.edges.tolist()}) == city.n_edges  # no duplicate edges
    assert all(u != v for u, v in city.edges.tolist())


def test_config_is_checked():
    with pytest.raises(ValueError):
        StitchConfig(merge_px=0)


def test_a_neighbour_mends_two_ends_its_owner_left_dangling():
    # Two curbs of the left patch end at (98, 20) and (99, 80) and it saw no edge between them;
    # the right patch, with both ends in view (>= 8 px inside its window, which starts at x = 90),
    # did. The edge's midpoint (x = 98.5) is the left patch's to judge, so it is a repair.
    left = graph([[20, 20], [98, 20], [99, 80], [20, 80]], [[0, 1], [2, 3]])
    right = graph([[98, 20], [99, 80]], [[0, 1]], edge_scores=np.array([0.7]))
    city = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID)
    assert city.n_edges == 3 and pieces(city) == 1
    assert sorted(np.bincount(city.edges.ravel()).tolist()) == [1, 1, 2, 2]
    assert stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID, StitchConfig(repair=False)).n_edges == 2
    # An end that already continues is not joined again.
    branchy = graph([[20, 20], [98, 20], [99, 80], [20, 80], [60, 50]], [[0, 1], [2, 3], [2, 4]])
    assert stitch_patch_graphs({(0, 0): branchy, (0, 1): right}, GRID).n_edges == 3


def test_a_neighbours_edge_along_its_own_window_border_is_no_repair():
    # Two curbs of the left patch end at x = 91, where they leave the right patch's window (it
    # starts at x = 90). The right patch's edge between those two cut points runs along its
    # border, across whatever lies between: not a repair.
    left = graph([[20, 20], [91, 20], [91, 80], [20, 80]], [[0, 1], [2, 3]])
    right = graph([[91, 20], [91, 80]], [[0, 1]], edge_scores=np.array([0.9]))
    assert stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID).n_edges == 2
    # The same edge 10 px further in (both ends in view) is one.
    inside = graph([[20, 20], [100, 20], [99, 80], [20, 80]], [[0, 1], [2, 3]])
    seen = graph([[100, 20], [99, 80]], [[0, 1]], edge_scores=np.array([0.9]))
    assert stitch_patch_graphs({(0, 0): inside, (0, 1): seen}, GRID).n_edges == 3


def pieces(city: BoundaryGraph) -> int:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = city.edges
    return connected_components(
        coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(city.n_vertices,) * 2), directed=False
    )[0]


def test_ends_cut_by_the_window_borders_are_mended_onto_the_edge_they_lie_on():
    # One curb along y = 50. The left patch's edge stops at x = 105, 5 px from its window's right
    # side; the right patch's starts at x = 91, 1 px inside its window's left side. Neither
    # extracted the other's cut end (no keypoint there), so snapping finds nothing: each end lies
    # on the other side's edge.
    left = graph([[20, 50], [105, 50]], [[0, 1]])
    right = graph([[91, 50], [180, 50]], [[0, 1]])
    broken = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID, StitchConfig(mend_px=0))
    assert broken.n_edges == 2 and pieces(broken) == 2
    city = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID)
    assert pieces(city) == 1 and city.n_vertices == 4 and city.n_edges == 3  # 20 - 91 - 105 - 180
    assert sorted(np.bincount(city.edges.ravel()).tolist()) == [1, 1, 2, 2]
    lengths = sorted(float(np.linalg.norm(np.subtract(*city.vertices[e]))) for e in city.edges)
    assert lengths == [14, 71, 75]


def test_an_end_beside_the_edge_gets_a_short_seam_edge_and_splits_a_shaped_edge():
    arc = np.array([[20.0, 50], [60, 50], [100, 50]])
    left = graph(
        [[20, 50], [100, 50]], [[0, 1]], edge_kinds=["corner"], edge_polylines=[arc], edge_scores=np.array([0.8])
    )
    right = graph([[91, 53], [180, 53]], [[0, 1]], edge_kinds=["normal"], edge_scores=np.array([0.6]))
    city = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID)
    assert pieces(city) == 1 and city.n_edges == 4
    seam = city.edge_kinds.index("seam")
    assert sorted(map(tuple, city.vertices[city.edges[seam]].tolist())) == [(91, 50), (91, 53)]
    assert city.edge_scores[seam] == 0.6 and city.edge_patches[seam].tolist() == [0, 1]
    corners = [k for k, kind in enumerate(city.edge_kinds) if kind == "corner"]
    assert len(corners) == 2  # the corner edge, split at (91, 50), keeps its shape on both sides
    for k in corners:
        line, (u, v) = city.edge_polyline(k), city.edges[k]
        assert np.array_equal(line[0], city.vertices[u]) and np.array_equal(line[-1], city.vertices[v])
    assert sum(float(np.abs(np.diff(city.edge_polyline(k)[:, 0])).sum()) for k in corners) == 80


def test_a_cut_end_a_blob_width_beside_the_neighbours_edge_is_mended():
    # The right window starts at x = 90: the blob cut there gives the right patch a vertex 12 px
    # below the curb the left patch sees whole (y = 50), further than snapping's 5 px.
    left = graph([[20, 50], [100, 50]], [[0, 1]])
    right = graph([[91, 62], [130, 50], [180, 50]], [[0, 1], [1, 2]])
    city = stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID)
    assert pieces(city) == 1
    seam = city.edge_kinds.index("seam")
    assert sorted(map(tuple, city.vertices[city.edges[seam]].tolist())) == [(91, 50), (91, 62)]
    assert pieces(stitch_patch_graphs({(0, 0): left, (0, 1): right}, GRID, StitchConfig(mend_px=5))) == 2


def test_ends_away_from_a_window_border_or_from_any_edge_stay_dangling():
    # An end 30 px inside its window, 3 px from another curb, is a real end as far as stitching
    # knows; so is a border end 20 px from the nearest edge (beyond the 15 px mending radius).
    inner = graph([[20, 50], [70, 50], [60, 53], [60, 90]], [[0, 1], [2, 3]])
    assert stitch_patch_graphs({(0, 0): inner, (0, 1): BoundaryGraph()}, GRID).n_edges == 2
    left = graph([[20, 50], [100, 50]], [[0, 1]])
    far = graph([[91, 70], [180, 70]], [[0, 1]])
    city = stitch_patch_graphs({(0, 0): left, (0, 1): far}, GRID)
    assert city.n_edges == 2 and pieces(city) == 2


def test_config_rejects_a_negative_mend_radius():
    with pytest.raises(ValueError):
        StitchConfig(mend_px=-1)
