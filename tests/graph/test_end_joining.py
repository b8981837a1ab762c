"""Dangling ends joined across supported gaps: hand-built graphs on hand-drawn boundary maps."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.end_attachment import ATTACH
from csboundary.graph.end_joining import (
    JOIN,
    EndJoinConfig,
    end_headings,
    join_candidates,
    join_ends,
)
from csboundary.graph.settings import GraphOverrides, GraphSettings

ON = EndJoinConfig(max_px=20)


def line_map(row: int = 50, x0: int = 0, x1: int = 100, size: int = 100) -> np.ndarray:
    """A one-pixel boundary along ``row`` from column x0 to x1 - 1."""
    m = np.zeros((size, size), np.float32)
    m[row, x0:x1] = 1.0
    return m


def graph(vertices, edges) -> BoundaryGraph:
    edges = np.array(edges, np.int64).reshape(-1, 2)
    return BoundaryGraph(
        np.array(vertices, float).reshape(-1, 2),
        edges,
        edge_kinds=["normal"] * len(edges),
        edge_polylines=[None] * len(edges),
        edge_scores=np.ones(len(edges)),
    )


def two_pieces(gap_start: float = 30.5, gap_end: float = 45.5) -> BoundaryGraph:
    """Two pieces of the row-50 line, broken between columns ``gap_start`` and ``gap_end``."""
    return graph([(5.5, 50.5), (gap_start, 50.5), (gap_end, 50.5), (80.5, 50.5)], [(0, 1), (2, 3)])


def test_headings_point_out_of_the_line_at_its_ends():
    ends, heading = end_headings(two_pieces())
    assert ends.tolist() == [0, 1, 2, 3]
    np.testing.assert_allclose(heading, [(-1, 0), (1, 0), (-1, 0), (1, 0)])


def test_heading_comes_from_the_polyline_not_the_far_vertex():
    bent = BoundaryGraph(
        np.array([(10.5, 10.5), (30.5, 30.5)]),
        np.array([(0, 1)]),
        edge_polylines=[np.array([(10.5, 10.5), (30.5, 10.5), (30.5, 30.5)])],
    )
    _, heading = end_headings(bent)
    np.testing.assert_allclose(heading, [(-1, 0), (0, 1)])  # vertex 1 was heading down when the line stopped


def test_a_break_in_a_straight_boundary_is_joined():
    joined = join_ends(two_pieces(), line_map(), ON)
    assert joined.n_edges == 3
    assert sorted(joined.edges[-1].tolist()) == [1, 2]
    assert joined.edge_kinds[-1] == JOIN
    assert joined.edge_scores[-1] == pytest.approx(1.0)
    assert joined.edges[:2].tolist() == [[0, 1], [2, 3]]  # the old edges are kept as they were


def test_a_break_longer_than_the_limit_stays():
    assert join_ends(two_pieces(30.5, 55.5), line_map(), ON).n_edges == 2  # 25 px > 20


def test_off_returns_the_graph_itself():
    g = two_pieces()
    assert join_ends(g, line_map(), EndJoinConfig()) is g


def test_no_boundary_in_the_gap_no_join():
    m = line_map()
    m[50, 31:48] = 0.0  # 17 px without boundary: 13 after the 2 px max filter, more than max_gap_px (10)
    assert join_ends(two_pieces(30.5, 48.5), m, ON).n_edges == 2
    m[50, 39:41] = 1.0  # now two gaps of 4 px after the filter, and a mean above 0.3
    assert join_ends(two_pieces(30.5, 48.5), m, ON).n_edges == 3


def test_a_turn_sharper_than_the_limit_is_not_joined():
    # the second piece starts 15 px below the first one's end, heading down: a 90 degree turn
    g = graph([(5.5, 50.5), (30.5, 50.5), (30.5, 65.5), (30.5, 90.5)], [(0, 1), (2, 3)])
    m = np.zeros((100, 100), np.float32)
    m[50, 5:31] = m[50:91, 30] = 1.0
    assert len(join_candidates(g, ON)) == 0
    assert join_ends(g, m, ON).n_edges == 2
    assert join_ends(g, m, EndJoinConfig(max_px=20, max_turn_deg=90)).n_edges == 3


def test_the_two_ends_of_one_piece_are_not_joined_to_each_other_again():
    g = graph([(30.5, 50.5), (45.5, 50.5)], [(0, 1)])
    assert len(join_candidates(g, ON)) == 0


def test_a_lone_vertex_in_the_gap_links_both_ends():
    g = graph([(5.5, 50.5), (30.5, 50.5), (40.5, 50.5), (50.5, 50.5), (80.5, 50.5)], [(0, 1), (3, 4)])
    joined = join_ends(g, line_map(), EndJoinConfig(max_px=12))
    assert sorted(tuple(sorted(e)) for e in joined.edges[2:].tolist()) == [(1, 2), (2, 3)]


def test_closest_pair_first_and_one_join_per_end():
    # end 1 (heading right) is 10 px from end 2 and 14 px from the lone vertex 4; end 2 heads
    # left, away from 4. 1 joins 2 first, and then has no join left for 4.
    g = graph([(5.5, 50.5), (30.5, 50.5), (40.5, 50.5), (60.5, 50.5), (44.5, 50.5)], [(0, 1), (2, 3)])
    assert [sorted(p) for p in join_candidates(g, ON).tolist()] == [[1, 2], [1, 4]]
    joined = join_ends(g, line_map(), ON)
    assert joined.n_edges == 3 and sorted(joined.edges[2].tolist()) == [1, 2]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.floats(2, 97), st.floats(2, 97)), min_size=2, max_size=16),
    st.floats(5, 60),
    st.floats(0, 180),
)
def test_joins_are_short_new_and_keep_degrees_at_most_two(points, max_px, turn):
    vertices = np.array(points)
    edges = [(k, k + 1) for k in range(0, len(vertices) - 1, 2)]  # disjoint pieces: every vertex an end
    g = graph(vertices, edges)
    joined = join_ends(g, np.ones((100, 100), np.float32), EndJoinConfig(max_px=max_px, max_turn_deg=turn))
    assert joined.edges[: len(edges)].tolist() == [list(e) for e in edges]
    new = joined.edges[len(edges) :]
    degree = np.bincount(joined.edges.ravel(), minlength=joined.n_vertices)
    assert degree.max(initial=0) <= 2
    assert np.all(np.linalg.norm(vertices[new[:, 0]] - vertices[new[:, 1]], axis=1) <= max_px + 1e-9)
    pairs = {tuple(sorted(e)) for e in joined.edges.tolist()}
    assert len(pairs) == joined.n_edges  # no edge twice


@pytest.mark.parametrize("option, field", [("join_ends", "max_px"), ("attach_backed", "attach_px")])
def test_bundle_carries_the_setting_and_a_command_line_value_overrides_it(tmp_path, option, field):
    import torch

    from csboundary.graph.settings import GraphSettings
    from csboundary.models.checkpoint import load_checkpoint
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor
    from helpers import shipped_parts

    shipped_parts(tmp_path)
    make_bundle(
        tmp_path / "fpn.pt", tmp_path / "afanet.pt", tmp_path / "b.pt", GraphSettings().replaced(**{option: 40})
    )
    assert getattr(PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu")).settings.join, field) == 40
    assert not load_predictor(
        tmp_path / "b.pt", "cpu", GraphOverrides(**{option: 0}), engine="torch"
    ).settings.join.active
    make_bundle(tmp_path / "fpn.pt", tmp_path / "afanet.pt", tmp_path / "off.pt")
    assert load_checkpoint(tmp_path / "off.pt", ("bundle",))["inference"][option] == 0  # the bundle key is the option
    assert not PatchPredictor.load(tmp_path / "off.pt", torch.device("cpu")).settings.join.active
    assert (
        getattr(
            load_predictor(tmp_path / "off.pt", "cpu", GraphOverrides(**{option: 25}), engine="torch").settings.join,
            field,
        )
        == 25
    )


def test_the_predictor_joins_after_the_fill_on_the_boundary_map():
    from csboundary.pipeline.prediction.patch import PatchPredictor

    maps = np.zeros((2, 100, 100), np.float32)
    maps[1] = line_map()
    predictor = PatchPredictor(None, None, None, settings=GraphSettings(join=ON))
    joined = predictor.finished(None, maps, two_pieces())
    assert joined.edge_kinds[-1] == JOIN and sorted(joined.edges[-1].tolist()) == [1, 2]
    assert PatchPredictor(None, None, None).finished(None, maps, two_pieces()).n_edges == 2


def side_street(stop_row: float = 30.5) -> BoundaryGraph:
    """The row-50 road (one edge) and a side street down column 50 that stops ``stop_row``."""
    return graph([(0.5, 50.5), (99.5, 50.5), (50.5, 0.5), (50.5, stop_row)], [(0, 1), (2, 3)])


def tee_map(gap_from: int = 100) -> np.ndarray:
    """The road along row 50 and the side street down column 50 to it, blank from ``gap_from`` on."""
    m = line_map()
    m[: min(gap_from, 50), 50] = 1.0
    return m


ATTACH_ON = EndJoinConfig(attach_px=30)


def test_an_end_short_of_a_line_the_map_leads_to_is_attached_and_the_line_split():
    tee = join_ends(side_street(), tee_map(), ATTACH_ON)
    assert tee.n_vertices == 5 and np.allclose(tee.vertices[4], (50.5, 50.5))  # the foot, a new vertex on the road
    attached = [sorted(tee.edges[k].tolist()) for k, kind in enumerate(tee.edge_kinds) if kind == ATTACH]
    assert attached == [[3, 4]]
    assert sorted(map(sorted, tee.edges.tolist())) == [[0, 4], [1, 4], [2, 3], [3, 4]]


def test_no_attachment_across_a_gap_the_map_does_not_back():
    assert join_ends(side_street(), tee_map(gap_from=32), ATTACH_ON).n_edges == 2  # 18 px blank > max_gap_px 10
    assert join_ends(side_street(), tee_map(), EndJoinConfig(attach_px=15)).n_edges == 2  # 20 px away: beyond 15


def test_ends_joined_to_each_other_are_not_attached_as_well():
    # a break in the road 15 px wide, the side street's end 25 px above it: the road's ends join
    # each other first, then the street's end reaches the joined road
    broken = graph(
        [(0.5, 50.5), (40.5, 50.5), (55.5, 50.5), (99.5, 50.5), (70.5, 0.5), (70.5, 25.5)], [(0, 1), (2, 3), (4, 5)]
    )
    m = line_map()
    m[:50, 70] = 1.0
    done = join_ends(broken, m, EndJoinConfig(max_px=20, attach_px=30))
    kinds = sorted(done.edge_kinds)
    assert kinds.count(JOIN) == 1 and kinds.count(ATTACH) == 1
    assert np.bincount(done.edges.ravel()).max() == 3  # the foot on the road: road in, road out, the street
