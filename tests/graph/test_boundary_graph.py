"""BoundaryGraph: construction from polylines, lengths, world coordinates, JSON round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString

from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph

T = Affine(0.5, 0, 583000.0, 0, -0.5, 4508000.0)


def test_polylines_share_their_common_points():
    g = BoundaryGraph.from_polylines([np.array([[0, 0], [3, 4], [3, 10]]), np.array([[3, 10], [9, 10]])])
    assert g.n_vertices == 4 and g.n_edges == 3
    assert sorted(g.edge_lengths().tolist()) == [5.0, 6.0, 6.0]


def test_edge_polyline_overrides_straight_segment():
    arc = np.array([[0, 0], [1, 1], [2, 0]], float)
    g = BoundaryGraph(np.array([[0, 0], [2, 0]]), np.array([[0, 1]]), edge_polylines=[arc], edge_kinds=["corner"])
    assert g.edge_lengths()[0] == pytest.approx(2 * np.sqrt(2))
    assert g.to_linestrings()[0].equals(LineString(arc))


def test_edges_must_name_existing_vertices():
    with pytest.raises(ValueError):
        BoundaryGraph(np.zeros((2, 2)), np.array([[0, 2]]))


def test_world_lines_round_trip_through_pixels():
    line = LineString([(583010.0, 4507990.0), (583020.0, 4507990.0)])
    g = BoundaryGraph.from_world_lines([line], T)
    assert g.vertices.tolist() == [[20.0, 20.0], [40.0, 20.0]]
    assert g.to_linestrings(world=True)[0].equals_exact(line, 1e-9)


@settings(max_examples=40, deadline=None)
@given(
    points=st.lists(st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)), min_size=2, max_size=12, unique=True),
    with_extras=st.booleans(),
)
def test_json_round_trip(points, with_extras, tmp_path_factory):
    pts = np.array(points)
    g = BoundaryGraph.from_polylines([pts], transform=T, crs="EPSG:32618")
    if with_extras:
        g.edge_scores = np.linspace(0, 1, g.n_edges)
        g.edge_kinds = ["normal"] * g.n_edges
        g.vertex_kinds = ["isolated"] * g.n_vertices
        g.edge_patches = np.stack([np.arange(g.n_edges), np.arange(g.n_edges)[::-1]], axis=1)
    path = tmp_path_factory.mktemp("g") / "g.json"
    back = BoundaryGraph.read_json(g.write_json(path))
    assert np.array_equal(back.vertices, g.vertices) and np.array_equal(back.edges, g.edges)
    assert back.transform == T and back.crs == "EPSG:32618"
    if with_extras and g.n_edges:  # (points closer than the snap make a graph without edges: nothing per edge to keep)
        assert np.allclose(back.edge_scores, g.edge_scores) and back.edge_kinds == g.edge_kinds
        assert np.array_equal(back.edge_patches, g.edge_patches)
    elif not with_extras:
        assert back.edge_patches is None
    data = json.loads(path.read_text())
    assert data["vertices"][0]["xy"] == pytest.approx(list(T @ tuple(pts[0])))


def test_bad_graph_files_name_the_file(tmp_path):
    p = tmp_path / "g.json"
    p.write_text("{not json")
    with pytest.raises(InputError, match="g.json: not JSON"):
        BoundaryGraph.read_json(p)
    p.write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(InputError, match="not a csboundary-graph"):
        BoundaryGraph.read_json(p)
    p.write_text(
        json.dumps(
            {"format": "csboundary-graph", "version": 1, "vertices": [{"px": [0, 0]}], "edges": [{"u": 0, "v": 5}]}
        )
    )
    with pytest.raises(InputError, match="malformed"):
        BoundaryGraph.read_json(p)
