"""Merged chains and the georeferenced outputs (GeoPackage, GeoJSON, graph JSON), checked on
hand-built graphs whose answers are worked out by hand, plus a property over random graphs."""

from __future__ import annotations

import json

import geopandas as gpd
import numpy as np
import pyogrio
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.ground_truth import read_ground_truth
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import chains, merge_chains
from csboundary.pipeline.outputs import prediction_files as outputs
from csboundary.pipeline.outputs.prediction_files import graph_frames, write_graph_outputs

CRS = "EPSG:32618"
NORTH_UP = Affine(0.5, 0.0, 500000.0, 0.0, -0.5, 4400000.0)  # 0.5 m/px


def graph(vertices, edges, **kw) -> BoundaryGraph:
    kw.setdefault("transform", NORTH_UP)
    kw.setdefault("crs", CRS)
    return BoundaryGraph(np.array(vertices, dtype=float), np.array(edges, dtype=np.int64).reshape(-1, 2), **kw)


def world(transform, points):
    """transform @ (col, row, 1), written out independently of the code under test."""
    return np.array([transform @ (float(c), float(r)) for c, r in points])


def used_edges(merged) -> list[int]:
    return sorted(int(k) for chain in merged for k in chain.edges)


# -- merging ---------------------------------------------------------------------------------------
def test_t_junction_gives_three_chains_meeting_at_the_junction():
    #  A - a - J - b - B      (A=0 a=1 J=2 b=3 B=4 C=5), J has degree 3
    #          |
    #          C
    g = graph([[0, 0], [5, 0], [10, 0], [15, 0], [20, 0], [10, 10]], [[0, 1], [1, 2], [2, 3], [3, 4], [2, 5]])
    merged = merge_chains(g)
    assert [c.vertices.tolist() for c in merged] == [[0, 1, 2], [2, 3, 4], [2, 5]]
    assert [c.edges.tolist() for c in merged] == [[0, 1], [2, 3], [4]]
    assert not any(c.closed for c in merged)
    boundaries, edges = graph_frames(g)
    assert boundaries["n_edges"].tolist() == [2, 2, 1]
    assert boundaries["length_m"].tolist() == pytest.approx([5.0, 5.0, 5.0])
    assert edges["boundary_id"].tolist() == [0, 0, 1, 1, 2]


def test_l_of_two_edges_is_one_line_with_exact_coordinates_length_and_attributes():
    # the second edge is stored from its far end, so it is walked backwards
    g = graph(
        [[0, 0], [10, 0], [10, 20]],
        [[0, 1], [2, 1]],
        edge_scores=np.array([0.2, 0.8]),
        edge_kinds=["normal", "normal"],
        edge_patches=[[3, 4], [3, 5]],
    )
    (chain,) = merge_chains(g)
    assert chain.vertices.tolist() == [0, 1, 2]
    assert chain.reversed.tolist() == [False, True]
    np.testing.assert_array_equal(chain.polyline, [[0, 0], [10, 0], [10, 20]])
    boundaries, _ = graph_frames(g)
    row = boundaries.iloc[0]
    np.testing.assert_allclose(
        np.asarray(row.geometry.coords), [[500000, 4400000], [500005, 4400000], [500005, 4399990]]
    )
    assert row.length_m == pytest.approx(15.0)  # 5 m + 10 m
    assert row.confidence_mean == pytest.approx((0.2 * 5 + 0.8 * 10) / 15)  # 0.6: weighted by length
    assert row.confidence_min == pytest.approx(0.2)
    assert row.corner_edges == 0
    assert row.patches == "3,4;3,5"


def test_curved_corner_edge_walked_backwards_is_reversed_into_the_line():
    # edge 0 is a corner stored from vertex 1 to vertex 0 along (10,10) -> (0,10) -> (0,0)
    corner = np.array([[10, 10], [0, 10], [0, 0]], dtype=float)
    g = graph(
        [[0, 0], [10, 10], [20, 10]],
        [[1, 0], [1, 2]],
        edge_kinds=["corner", "normal"],
        edge_polylines=[corner, None],
        edge_scores=np.array([0.5, 1.0]),
        edge_patches=[[7, 1], [7, 1]],
    )
    (chain,) = merge_chains(g)
    assert chain.vertices.tolist() == [0, 1, 2]
    assert chain.reversed.tolist() == [True, False]
    np.testing.assert_array_equal(chain.polyline, [[0, 0], [0, 10], [10, 10], [20, 10]])
    row = graph_frames(g)[0].iloc[0]
    assert row.length_m == pytest.approx(15.0)  # 20 px + 10 px at 0.5 m/px
    assert row.corner_edges == 1
    assert row.confidence_mean == pytest.approx((0.5 * 10 + 1.0 * 5) / 15)
    assert row.patches == "7,1"  # distinct patches only


def test_polyline_ends_are_pinned_to_their_vertices():
    off = np.array([[0.001, 0], [5, 5], [10, -0.002]])
    g = graph([[0, 0], [10, 0], [20, 0]], [[0, 1], [1, 2]], edge_polylines=[off, None])
    (chain,) = merge_chains(g)
    np.testing.assert_array_equal(chain.polyline, [[0, 0], [5, 5], [10, 0], [20, 0]])


def test_closed_loop_is_a_closed_ring():
    g = graph([[0, 0], [10, 0], [10, 10], [0, 10]], [[0, 1], [1, 2], [2, 3], [3, 0]])
    (chain,) = merge_chains(g)
    assert chain.closed
    np.testing.assert_array_equal(chain.polyline, [[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]])
    row = graph_frames(g)[0].iloc[0]
    assert row.geometry.is_closed and row.length_m == pytest.approx(20.0)


def test_parallel_edges_and_self_loops_use_every_edge_once():
    # 0 =(two parallel edges)= 1 is a loop of degree-2 vertices; 2 carries a self-loop;
    # 3 and 4 are joined by three parallel edges (degree 3: three one-edge chains)
    bump = np.array([[0, 0], [5, 5], [10, 0]], dtype=float)
    ring = np.array([[20, 0], [30, 0], [30, 10], [20, 0]], dtype=float)
    g = graph(
        [[0, 0], [10, 0], [20, 0], [40, 0], [50, 0]],
        [[0, 1], [0, 1], [2, 2], [3, 4], [3, 4], [4, 3]],
        edge_polylines=[None, bump, ring, None, None, None],
    )
    merged = merge_chains(g)
    assert used_edges(merged) == list(range(6))
    by_first_edge = {int(c.edges[0]): c for c in merged}
    pair = by_first_edge[0]
    assert pair.closed and pair.reversed.tolist() == [False, True]
    np.testing.assert_array_equal(pair.polyline, [[0, 0], [10, 0], [5, 5], [0, 0]])
    loop = by_first_edge[2]
    assert loop.closed and loop.vertices.tolist() == [2, 2]
    np.testing.assert_array_equal(loop.polyline, ring)
    assert sorted(len(c.edges) for c in merged) == [1, 1, 1, 1, 2]
    boundaries, _ = graph_frames(g)
    assert boundaries["length_m"].sum() == pytest.approx(g.edge_lengths().sum() * 0.5)


def test_self_loop_without_shape_and_isolated_vertices_do_not_crash():
    g = graph([[0, 0], [3, 3], [9, 9]], [[0, 0], [0, 1]])
    merged = merge_chains(g)
    assert used_edges(merged) == [0, 1]
    assert {tuple(c.vertices.tolist()) for c in merged} == {(0, 0), (0, 1)}


def test_chains_returns_anchors_for_the_metrics():
    found = chains(5, np.array([[0, 1], [1, 2], [3, 4], [4, 3]]))
    assert found.vertices == [[0, 1, 2], [3, 4, 3]]
    assert found.edges == [[0, 1], [2, 3]]
    assert found.anchor.tolist() == [True, False, True, True, False]


# -- files -------------------------------------------------------------------------------------------
SKEWED = Affine(0.5, 0.1, 583000.0, 0.05, -0.5, 4507200.0)  # rotation/shear: catches swapped terms


def scored_graph(transform=SKEWED, crs=CRS) -> BoundaryGraph:
    arc = np.array([[10, 0], [14, 2], [16, 6], [16, 10]], dtype=float)
    return graph(
        [[0, 0], [10, 0], [16, 10], [30, 10], [16, 30]],
        [[0, 1], [1, 2], [2, 3], [4, 2]],
        edge_polylines=[None, arc, None, None],
        edge_kinds=["normal", "corner", "normal", "skeleton"],
        edge_scores=np.array([0.9, np.nan, 0.4, 0.7]),
        edge_patches=[[0, 0], [0, 1], [0, 1], [-1, -1]],
        transform=transform,
        crs=crs,
    )


def test_geopackage_reads_back_in_the_graphs_crs_and_world_coordinates(tmp_path):
    g = scored_graph()
    paths = write_graph_outputs(g, tmp_path / "out")
    assert paths == {
        "gpkg": tmp_path / "out/boundaries.gpkg",
        "geojson": tmp_path / "out/boundaries.geojson",
        "graph_json": tmp_path / "out/graph.json",
    }
    assert sorted(name for name, _ in pyogrio.list_layers(paths["gpkg"])) == ["edges", "road_boundaries"]

    boundaries = gpd.read_file(paths["gpkg"], layer="road_boundaries")
    assert boundaries.crs == CRS
    merged = merge_chains(g)
    assert len(boundaries) == len(merged) == 3  # junction at vertex 2: 0-1-2, 2-3, 2-4
    for row, chain in zip(boundaries.itertuples(), merged):
        np.testing.assert_allclose(np.asarray(row.geometry.coords), world(SKEWED, chain.polyline), rtol=0, atol=1e-6)
        assert row.length_m == pytest.approx(row.geometry.length)
    first = boundaries.iloc[0]  # edges 0 (0.9) and 1 (unscored corner): NaN ignored
    assert first.confidence_mean == pytest.approx(0.9) and first.confidence_min == pytest.approx(0.9)
    assert first.corner_edges == 1 and first.skeleton_edges == 0 and first.n_edges == 2 and first.patches == "0,0;0,1"
    assert boundaries["skeleton_edges"].tolist() == [0, 0, 1]  # edge 3 (4-2) was filled in from the skeleton
    assert boundaries.iloc[2].patches == ""  # edge 3's patch is unknown

    edges = gpd.read_file(paths["gpkg"], layer="edges")
    assert edges.crs == CRS
    for k, row in enumerate(edges.itertuples()):
        np.testing.assert_allclose(
            np.asarray(row.geometry.coords), world(SKEWED, g.edge_polyline(k)), rtol=0, atol=1e-6
        )
    assert edges["u"].tolist() == [0, 1, 2, 4] and edges["v"].tolist() == [1, 2, 3, 2]
    assert edges["corner"].tolist() == [False, True, False, False]
    assert edges["kind"].tolist() == ["normal", "corner", "normal", "skeleton"]
    assert edges["patch_row"].tolist() == [0, 0, 0, -1] and edges["patch_col"].tolist() == [0, 1, 1, -1]
    np.testing.assert_allclose(edges["confidence"], [0.9, np.nan, 0.4, 0.7])
    assert edges["length_m"].sum() == pytest.approx(boundaries["length_m"].sum())

    geojson = gpd.read_file(paths["geojson"])
    assert geojson.crs == CRS and len(geojson) == 3
    np.testing.assert_allclose(
        np.asarray(geojson.geometry.iloc[1].coords), np.asarray(boundaries.geometry.iloc[1].coords)
    )
    assert len(read_ground_truth(paths["gpkg"], crs=CRS)) == 3  # usable as an evaluation input

    back = BoundaryGraph.read_json(paths["graph_json"])
    np.testing.assert_array_equal(back.vertices, g.vertices)
    assert back.crs == CRS and back.transform == SKEWED
    xy = [v["xy"] for v in json.loads(paths["graph_json"].read_text())["vertices"]]
    np.testing.assert_allclose(xy, world(SKEWED, g.vertices))


def test_empty_graph_writes_empty_files_with_the_schema(tmp_path):
    paths = write_graph_outputs(graph(np.zeros((0, 2)), np.zeros((0, 2))), tmp_path, stem="city")
    assert paths["gpkg"].name == "city.gpkg" and paths["geojson"].name == "city.geojson"
    info = pyogrio.read_info(paths["gpkg"], layer="road_boundaries")
    assert info["features"] == 0 and info["geometry_type"] == "LineString" and info["crs"] == CRS
    assert list(info["fields"]) == [
        "boundary_id",
        "length_m",
        "n_edges",
        "confidence_mean",
        "confidence_min",
        "review_draft",
        "corner_edges",
        "skeleton_edges",
        "patches",
    ]
    info = pyogrio.read_info(paths["gpkg"], layer="edges")
    assert info["features"] == 0
    assert list(info["fields"]) == [
        "edge_id",
        "boundary_id",
        "u",
        "v",
        "confidence",
        "corner",
        "kind",
        "patch_row",
        "patch_col",
        "length_m",
    ]
    assert json.loads(paths["geojson"].read_text())["features"] == []
    assert BoundaryGraph.read_json(paths["graph_json"]).n_edges == 0


def test_graph_without_crs_writes_files_without_crs(tmp_path):
    paths = write_graph_outputs(scored_graph(crs=None), tmp_path)
    assert gpd.read_file(paths["gpkg"], layer="road_boundaries").crs is None
    assert gpd.read_file(paths["gpkg"], layer="edges").crs is None
    assert "crs" not in json.loads(paths["geojson"].read_text())
    assert json.loads(paths["graph_json"].read_text())["crs"] is None


def test_graph_without_transform_is_refused_before_writing(tmp_path):
    with pytest.raises(ValueError, match="transform"):
        write_graph_outputs(scored_graph(transform=None), tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_interrupted_write_leaves_no_file_under_a_final_name(tmp_path, monkeypatch):
    real = outputs._write_layer
    calls = []

    def fail_on_second_layer(*args, **kwargs):
        calls.append(args[2])
        if len(calls) == 2:
            raise KeyboardInterrupt  # after the first layer is on disk
        real(*args, **kwargs)

    monkeypatch.setattr(outputs, "_write_layer", fail_on_second_layer)
    with pytest.raises(KeyboardInterrupt):
        write_graph_outputs(scored_graph(), tmp_path / "fresh")
    assert list((tmp_path / "fresh").iterdir()) == []  # no final files, no partial ones

    # a previous run's complete files are kept untouched
    monkeypatch.setattr(outputs, "_write_layer", real)
    paths = write_graph_outputs(scored_graph(), tmp_path / "old")
    before = {key: path.read_bytes() for key, path in paths.items()}
    monkeypatch.setattr(outputs, "_write_layer", fail_on_second_layer)
    calls.clear()
    with pytest.raises(KeyboardInterrupt):
        write_graph_outputs(graph([[0, 0], [1, 1]], [[0, 1]]), tmp_path / "old")
    assert {key: path.read_bytes() for key, path in paths.items()} == before
    assert sorted(p.name for p in (tmp_path / "old").iterdir()) == [
        "boundaries.geojson",
        "boundaries.gpkg",
        "graph.json",
    ]


# -- property ------------------------------------------------------------------------------------
@st.composite
def random_graphs(draw):
    n = draw(st.integers(1, 8))
    coord = st.floats(-100, 100, allow_nan=False)
    vertices = np.array(draw(st.lists(st.tuples(coord, coord), min_size=n, max_size=n)), dtype=float)
    pairs = draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=14))  # loops, duplicates
    polylines = []
    for u, v in pairs:
        interior = draw(st.lists(st.tuples(coord, coord), max_size=3))
        polylines.append(np.array([vertices[u], *interior, vertices[v]], dtype=float) if interior else None)
    return graph(vertices, pairs, edge_polylines=polylines, transform=Affine(0.3, 0, 1000, 0, -0.3, 2000))


@settings(max_examples=150, deadline=None)
@given(g=random_graphs())
def test_merged_chains_cover_every_edge_once_and_keep_the_total_length(g):
    merged = merge_chains(g)
    assert used_edges(merged) == list(range(g.n_edges))
    degree = np.bincount(g.edges.ravel(), minlength=g.n_vertices)
    for chain in merged:
        assert len(chain.vertices) == len(chain.edges) + 1
        for i, (k, back) in enumerate(zip(chain.edges, chain.reversed)):
            step = tuple(chain.vertices[i : i + 2][::-1]) if back else tuple(chain.vertices[i : i + 2])
            assert step == tuple(g.edges[k])
        assert all(degree[chain.vertices[1:-1]] == 2)  # chains only pass through degree-2 vertices
        np.testing.assert_array_equal(chain.polyline[[0, -1]], g.vertices[chain.vertices[[0, -1]]])
        assert chain.closed == (chain.vertices[0] == chain.vertices[-1])
    total = sum(float(np.linalg.norm(np.diff(c.polyline, axis=0), axis=1).sum()) for c in merged)
    assert total == pytest.approx(g.edge_lengths().sum(), rel=1e-9, abs=1e-9)
    boundaries, edges = graph_frames(g)
    assert boundaries["length_m"].sum() == pytest.approx(0.3 * total, rel=1e-9, abs=1e-9)
    assert edges["length_m"].sum() == pytest.approx(0.3 * total, rel=1e-9, abs=1e-9)
    assert boundaries["confidence_mean"].isna().all()  # no scores: NaN, not an error


@pytest.mark.parametrize("scale", [1.0, 0.5, 0.37])
def test_the_overview_from_core_thumbnails_is_the_reduced_mosaic(shared_tiles, scale):
    """overview.png is assembled from each core's thumbnail taken when the FPN read the patch;
    it must be the picture a second, reduced pass over the imagery would give."""
    from csboundary.data.grid import GridConfig, PatchGrid
    from csboundary.data.raster import Mosaic
    from csboundary.viz.overlay import core_thumbnail, overview_from_thumbs

    with Mosaic.open(shared_tiles.directory) as mosaic:  # 120 x 80 px
        grid = PatchGrid.for_mosaic(mosaic, GridConfig(core=32, margin=6))
        thumbs = {p.index: core_thumbnail(mosaic.read(p.expanded), p, scale) for p in grid}
        whole = mosaic.read(mosaic.window, scale=scale) if scale != 1.0 else mosaic.read(mosaic.window)
        assert (
            overview_from_thumbs(grid, scale, lambda i: None if i == (1, 1) else thumbs[i]) is None
        )  # one missing: read instead
        built = overview_from_thumbs(grid, scale, thumbs.get)
    assert built.data.shape == whole.data.shape and built.valid.all() == whole.valid.all()
    difference = np.abs(built.data.astype(int) - whole.data.astype(int))
    if scale == 1.0:
        assert difference.max() == 0
    else:  # area averages of uniform noise over blocks cut at the cores' rounded edges instead of strips'
        assert np.median(difference) < 20
        assert np.allclose(built.data.mean(axis=(1, 2)), whole.data.mean(axis=(1, 2)), atol=2)
