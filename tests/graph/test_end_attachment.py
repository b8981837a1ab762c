"""Dangling ends joined to the line ahead of them (graph/end_attachment.py; the city graph's attach_px)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.graph import BoundaryGraph
from csboundary.graph.end_attachment import attach_ends, dangling_ends
from csboundary.graph.fragments import fragment_lengths
from csboundary.graph.settings import GraphOverrides
from csboundary.graph.stitching import StitchConfig
from csboundary.pipeline.prediction.city_blocks import CityGraphRecipe, city_graph

# a road boundary along y = 100 from x = 0 to 300 (a corner edge with a shape), and a side
# street's boundary coming down x = 150 that stops 30 px short of it
ROAD = np.array([[0.0, 100], [150, 100], [300, 100]])


def side_street(stop_y: float = 70.0, x: float = 150.0) -> BoundaryGraph:
    vertices = np.array([[0.0, 100], [300, 100], [x, 0], [x, stop_y]])
    return BoundaryGraph(
        vertices,
        np.array([[0, 1], [2, 3]]),
        edge_kinds=["corner", "normal"],
        edge_polylines=[ROAD, None],
        edge_scores=np.array([0.9, 0.6]),
        edge_patches=np.array([[0, 0], [0, 1]]),
    )


def attached(graph: BoundaryGraph, radius: float = 40.0, **options) -> BoundaryGraph:
    ends, _, headings = dangling_ends(graph)
    return attach_ends(graph, ends, radius, "attach", headings, **options)


def test_dangling_ends_and_the_way_their_lines_were_going():
    ends, edges, headings = dangling_ends(side_street())
    assert ends.tolist() == [0, 1, 2, 3] and edges.tolist() == [0, 0, 1, 1]
    assert headings.tolist() == [
        [-1, 0],
        [1, 0],
        [0, -1],
        [0, 1],
    ]  # the road's ends outwards; the street's down at (150, 70)


def test_an_end_30_px_short_of_the_road_ahead_is_joined_to_it_and_the_road_split():
    city = attached(side_street())
    assert len(fragment_lengths(city)[1]) == 1 and city.n_vertices == 5 and city.n_edges == 4
    join = city.edge_kinds.index("attach")
    assert sorted(map(tuple, city.vertices[city.edges[join]].tolist())) == [(150, 70), (150, 100)]
    assert city.edge_scores[join] == 0.6 and city.edge_patches[join].tolist() == [0, 1]  # the end's own edge's
    halves = [k for k, kind in enumerate(city.edge_kinds) if kind == "corner"]
    assert len(halves) == 2 and sorted(city.edge_lengths()[halves].tolist()) == [150, 150]
    for k in halves:  # each half keeps the road's shape, ending on its vertices
        (u, v), line = city.edges[k], city.edge_polyline(k)
        assert np.array_equal(line[0], city.vertices[u]) and np.array_equal(line[-1], city.vertices[v])
    assert city.vertex_kinds[-1] == "attach"


def test_a_foot_within_the_merge_radius_of_a_vertex_reuses_it():
    city = attached(side_street(x=150.5), merge_px=1.0)  # the road's middle point is a polyline point, not a vertex
    assert city.n_vertices == 5
    graph = side_street(x=0.5)  # the foot (0.5, 100) is 0.5 px from the road's end vertex (0, 100)
    city = attached(graph, merge_px=1.0)
    join = city.edge_kinds.index("attach")
    assert city.n_vertices == 4 and 0 in city.edges[join].tolist()


@pytest.mark.parametrize(
    "graph, radius, why",
    [
        (side_street(stop_y=55), 40.0, "the road is 45 px away, beyond the radius"),
        (
            BoundaryGraph(np.array([[0.0, 100], [300, 100], [100, 70], [150, 70]]), np.array([[0, 1], [2, 3]])),
            40.0,
            "the line runs east, parallel to the road: it lies 90 degrees off its heading",
        ),
    ],
)
def test_an_end_not_heading_to_a_line_within_the_radius_stays(graph, radius, why):
    assert attached(graph, radius).n_edges == 2, why


def test_a_wider_turn_limit_lets_a_line_beside_the_end_be_reached():
    beside = BoundaryGraph(np.array([[0.0, 100], [300, 100], [100, 70], [150, 70]]), np.array([[0, 1], [2, 3]]))
    assert attached(beside, max_turn_deg=90.0).n_edges == 6  # both of its ends, straight down to the road


def test_the_line_ahead_wins_over_a_nearer_one_behind():
    # the street stops at (150, 70) heading down; a line 21 px away lies up and to its right
    # (behind), the road 40 px ahead
    vertices = np.array([[0.0, 110], [300, 110], [150, 0], [150, 70], [155, 50], [300, 50]])
    city = attached(BoundaryGraph(vertices, np.array([[0, 1], [2, 3], [4, 5]])), radius=45.0)
    joins = [
        sorted(map(tuple, city.vertices[city.edges[k]].tolist()))
        for k, kind in enumerate(city.edge_kinds)
        if kind == "attach"
    ]
    assert [(150, 70), (150, 110)] in joins
    assert [(150, 50), (155, 50)] in joins and len(joins) == 2  # that line's own end heads west onto the street


def test_an_end_is_never_joined_to_its_own_piece():
    hook = BoundaryGraph(np.array([[0.0, 100], [300, 100], [300, 70], [150, 70]]), np.array([[0, 1], [1, 2], [2, 3]]))
    assert attached(hook).n_edges == 3  # (150, 70) heads west, 30 px above its own piece's road


# one 400 x 200 patch: city_graph on a single patch graph is stitching plus the city steps
GRID = PatchGrid(400, 200, config=GridConfig(core=400, margin=10))


def test_the_city_graph_drops_a_short_piece_before_attaching_the_rest():
    """A 30 px scrap heading to the road is dropped as noise, not kept alive by a join; a long
    street is attached."""
    vertices = np.array([[0.0, 100], [300, 100], [150, 40], [150, 70], [250, 0], [250, 70]])
    graph = BoundaryGraph(
        vertices,
        np.array([[0, 1], [2, 3], [4, 5]]),
        edge_kinds=["normal"] * 3,
        edge_scores=np.ones(3),
        edge_patches=np.zeros((3, 2), int),
    )
    city = city_graph({(0, 0): graph}, GRID, CityGraphRecipe(StitchConfig(), None, min_fragment_px=50, attach_px=40))
    assert city.edge_kinds.count("attach") == 1 and len(fragment_lengths(city)[1]) == 1
    assert not np.any(np.all(city.vertices == [150, 40], axis=1))  # the scrap is gone
    assert city_graph({(0, 0): graph}, GRID, CityGraphRecipe(StitchConfig(), None, min_fragment_px=50)).n_edges == 2


def test_bundle_carries_the_attachment_and_a_command_line_value_overrides_it(tmp_path):
    import torch

    from csboundary.graph.settings import GraphSettings
    from csboundary.models.checkpoint import load_checkpoint
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor
    from helpers import shipped_parts

    shipped_parts(tmp_path)
    make_bundle(
        tmp_path / "fpn.pt", tmp_path / "afanet.pt", tmp_path / "b.pt", GraphSettings().replaced(attach_ends=40)
    )
    assert PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu")).settings.attach_px == 40
    assert (
        load_predictor(tmp_path / "b.pt", "cpu", GraphOverrides(attach_ends=0), engine="torch").settings.attach_px == 0
    )
    make_bundle(tmp_path / "fpn.pt", tmp_path / "afanet.pt", tmp_path / "off.pt")
    assert load_checkpoint(tmp_path / "off.pt", ("bundle",))["inference"]["attach_ends"] == 0
    assert PatchPredictor.load(tmp_path / "off.pt", torch.device("cpu")).settings.attach_px == 0
    assert (
        load_predictor(tmp_path / "off.pt", "cpu", GraphOverrides(attach_ends=25), engine="torch").settings.attach_px
        == 25
    )


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 200), st.integers(0, 200), st.integers(0, 200), st.integers(0, 200)),
        min_size=2,
        max_size=8,
    ),
    st.floats(5, 60),
)
def test_joins_are_short_go_between_pieces_and_only_add_their_own_length(segments, radius):
    """Random straight pieces: every attach edge is at most the radius long and joins a dangling
    end to what was another piece; an end joins at most once; splitting a line adds no length,
    except where the foot snaps onto a vertex within merge_px (1 px), which bends the line by at
    most 2 px: the graph grows by the joins' length plus 0 to 2 px per dangling end."""
    segments = [s for s in segments if (s[0], s[1]) != (s[2], s[3])]
    if len(segments) < 2:
        return
    graph = BoundaryGraph.from_polylines([np.array([[a, b], [c, d]], float) for a, b, c, d in segments])
    before_piece = fragment_lengths(graph)[0]
    vertex_piece = {}
    for e, (u, v) in enumerate(graph.edges):
        vertex_piece[int(u)] = vertex_piece[int(v)] = int(before_piece[e])
    ends, _, headings = dangling_ends(graph)
    joined = attach_ends(graph, ends, radius, "attach", headings)
    joins = [k for k, kind in enumerate(joined.edge_kinds or []) if kind == "attach"]
    lengths = joined.edge_lengths()
    assert np.all(lengths[joins] <= radius + 1e-9)
    bend = lengths.sum() - graph.edge_lengths().sum() - lengths[joins].sum()
    assert -1e-9 <= bend <= 2.0 * len(ends) + 1e-9
    starts = [next(int(x) for x in joined.edges[k] if int(x) < graph.n_vertices and x in ends) for k in joins]
    assert len(starts) == len(set(starts))  # one join per end
    for k, x in zip(joins, starts):
        other = [int(y) for y in joined.edges[k] if int(y) != x][0]
        if other < graph.n_vertices:  # the foot fell on an existing vertex: of another piece
            assert vertex_piece[other] != vertex_piece[x]


def test_an_end_takes_the_nearest_point_its_vetting_accepts():
    # the street stops at (150, 70) heading down; lines cross below it at y = 80 and y = 100
    vertices = np.array([[0.0, 100], [300, 100], [150, 0], [150, 70], [100, 80], [200, 80]])
    two_roads = BoundaryGraph(vertices, np.array([[0, 1], [2, 3], [4, 5]]))
    near = attached(two_roads)
    far = attached(two_roads, accept=lambda starts, feet: feet[:, 1] > 90)  # e.g. the map backs only the far join
    assert {tuple(near.vertices[v]) for v in range(near.n_vertices)} >= {(150.0, 80.0)}
    assert (150.0, 100.0) not in {tuple(v) for v in near.vertices.tolist()}
    assert (150.0, 100.0) in {tuple(v) for v in far.vertices.tolist()} and (150.0, 80.0) not in {
        tuple(v) for v in far.vertices.tolist()
    }
    assert attached(two_roads, accept=lambda starts, feet: np.zeros(len(feet), bool)) is two_roads
