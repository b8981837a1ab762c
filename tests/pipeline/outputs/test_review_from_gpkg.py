"""Review done with a GIS's own editing tools: the prediction's edges layer edited in a copy of
boundaries.gpkg (here through GeoPandas, which writes the GeoPackage QGIS edits) gives the same
graph as the review page's equivalent edits, through the same checks and record."""

from __future__ import annotations

import shutil
from pathlib import Path

import geopandas as gpd
import numpy as np
import pytest
from shapely.geometry import LineString, Polygon
from test_review_edits_checked import edits_file, world_line

from csboundary.data.windows import pixel_to_world
from csboundary.graph import BoundaryGraph
from csboundary.graph.chains import edge_line
from csboundary.graph.layer_edits import layer_edits
from csboundary.graph.review_edits import EditError
from helpers import run_cli


@pytest.fixture
def two_predictions(demo_run, tmp_path) -> tuple[Path, Path]:
    for name in ("page", "gis"):
        shutil.copytree(demo_run / "prediction", tmp_path / name)
    return tmp_path / "page", tmp_path / "gis"


def world(graph: BoundaryGraph, points: np.ndarray) -> np.ndarray:
    xs, ys = pixel_to_world(graph.transform, points[:, 0], points[:, 1])
    return np.stack([np.atleast_1d(xs), np.atleast_1d(ys)], axis=-1)


def test_the_same_edits_from_a_gis_layer_and_from_the_page_give_the_same_graph(two_predictions, tmp_path):
    page, gis = two_predictions
    graph = BoundaryGraph.read_json(page / "graph.json")
    degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    deleted = 3
    vertex = int(
        next(
            i
            for i in range(graph.n_vertices)
            if degree[i] == 2 and deleted not in np.flatnonzero((graph.edges == i).any(1))
        )
    )
    moved_to = graph.vertices[vertex] + np.array([4.0, -3.0])
    drawn = np.array([[500.0, 500.0], [540.0, 520.0], [600.0, 520.0]])  # graph pixels, away from every vertex
    area = np.array([[100.0, 100.0], [900.0, 100.0], [900.0, 900.0], [100.0, 900.0], [100.0, 100.0]])

    # the page's export
    features = [
        {
            "type": "Feature",
            "properties": {"action": "delete", "edge": deleted},
            "geometry": {"type": "LineString", "coordinates": world_line(graph, deleted)},
        },
        {
            "type": "Feature",
            "properties": {"action": "move", "vertex": vertex},
            "geometry": {"type": "Point", "coordinates": world(graph, moved_to[None])[0].tolist()},
        },
        {
            "type": "Feature",
            "properties": {"action": "add"},
            "geometry": {"type": "LineString", "coordinates": world(graph, drawn).tolist()},
        },
        {
            "type": "Feature",
            "properties": {"action": "complete"},
            "geometry": {"type": "Polygon", "coordinates": [world(graph, area).tolist()]},
        },
    ]
    done = run_cli("apply-review", str(page), str(edits_file(tmp_path / "edits.geojson", page, features)))
    assert done.returncode == 0, done.stderr

    # the same in the GIS: delete a feature, drag a vertex with both its lines, draw a line, draw a polygon
    edited = tmp_path / "edited.gpkg"
    shutil.copy(gis / "boundaries.gpkg", edited)
    edges = gpd.read_file(edited, layer="edges")
    assert (edges["edge_id"].to_numpy() == np.arange(graph.n_edges)).all()
    edges = edges[edges["edge_id"] != deleted].copy()
    new_end = world(graph, moved_to[None])[0]
    lines = []
    for (u, v), line in zip(edges[["u", "v"]].to_numpy(), edges.geometry):
        coords = np.asarray(line.coords)
        if u == vertex:
            coords[0] = new_end
        if v == vertex:
            coords[-1] = new_end
        lines.append(LineString(coords))
    edges = edges.set_geometry(gpd.GeoSeries(lines, index=edges.index, crs=edges.crs))
    row = {c: None for c in edges.columns if c != "geometry"}
    edges = gpd.GeoDataFrame(
        list(edges.to_dict("records")) + [{**row, "geometry": LineString(world(graph, drawn))}],
        geometry="geometry",
        crs=edges.crs,
    )
    edges.to_file(edited, layer="edges", driver="GPKG", engine="pyogrio")
    gpd.GeoDataFrame({"note": ["checked"]}, geometry=[Polygon(world(graph, area))], crs=edges.crs).to_file(
        edited, layer="complete", driver="GPKG", engine="pyogrio"
    )
    done = run_cli("apply-review", str(gis), str(edited))
    assert done.returncode == 0, done.stderr

    a, b = BoundaryGraph.read_json(page / "graph.json"), BoundaryGraph.read_json(gis / "graph.json")
    assert a.n_edges == b.n_edges == graph.n_edges and a.n_vertices == b.n_vertices  # one deleted, one drawn
    assert (
        np.allclose(a.vertices, b.vertices, atol=1e-6) and (a.edges == b.edges).all() and a.edge_kinds == b.edge_kinds
    )
    assert all(np.allclose(edge_line(a, k), edge_line(b, k), atol=1e-6) for k in range(a.n_edges))
    assert np.allclose(b.vertices[vertex], moved_to, atol=1e-6) and b.edge_kinds[-1] == "manual"
    import json

    page_record, gis_record = (json.loads((p / "review.json").read_text())["reviews"][-1] for p in (page, gis))
    for key in ("deleted_edges", "moved_vertices", "added_edges", "edge_index_map"):
        assert page_record[key] == gis_record[key], key
    assert len(gis_record["complete_areas"]) == 1


def test_a_line_redrawn_between_its_ends_replaces_its_edge_and_a_vertex_moved_twice_is_refused():
    from affine import Affine

    graph = BoundaryGraph(
        np.array([[10.0, 10.0], [50.0, 10.0], [90.0, 10.0]]),
        np.array([[0, 1], [1, 2]]),
        transform=Affine(0.5, 0, 1000, 0, -0.5, 2000),
        crs="EPSG:32618",
    )
    rows = [(k, int(u), int(v), world(graph, edge_line(graph, k))) for k, (u, v) in enumerate(graph.edges)]
    assert layer_edits(graph, rows) == []  # nothing changed, nothing to do
    assert layer_edits(graph, [(0, 0, 1, rows[0][3][::-1]), rows[1]]) == []  # a line reversed is the same edge
    bent = world(graph, np.array([[10.0, 10.0], [30.0, 20.0], [50.0, 10.0]]))
    actions = [f["properties"]["action"] for f in layer_edits(graph, [(0, 0, 1, bent), rows[1]])]
    assert actions == ["delete", "add"]
    two_places = [
        (0, 0, 1, world(graph, np.array([[10.0, 10.0], [52.0, 10.0]]))),
        (1, 1, 2, world(graph, np.array([[48.0, 10.0], [90.0, 10.0]]))),
    ]
    with pytest.raises(EditError, match="vertex 1 is moved to two places"):
        layer_edits(graph, two_places)
    with pytest.raises(EditError, match="written for another prediction"):
        layer_edits(graph, [(0, 1, 2, rows[0][3])])
    only_one = layer_edits(graph, [rows[0]])
    assert [(f["properties"]["action"], f["properties"]["edge"]) for f in only_one] == [("delete", 1)]


def test_a_layer_that_is_not_the_prediction_s_is_one_line(demo_run, tmp_path):
    from test_review_edits_checked import refused

    prediction = tmp_path / "prediction"
    shutil.copytree(demo_run / "prediction", prediction)
    (tmp_path / "junk.gpkg").write_text("not a geopackage")
    refused(prediction, tmp_path / "junk.gpkg", "not a readable GeoPackage")
    gpd.GeoDataFrame({"name": ["x"]}, geometry=[LineString([(0, 0), (1, 1)])], crs="EPSG:32618").to_file(
        tmp_path / "other.gpkg", layer="roads", driver="GPKG", engine="pyogrio"
    )
    refused(prediction, tmp_path / "other.gpkg", "has no boundaries or edges layer")


def test_the_review_layers_come_back_unchanged_as_no_edit_and_never_overwrite_the_prediction(demo_run, tmp_path):
    import pyogrio

    from csboundary.graph.boundaries import graph_boundaries

    prediction = tmp_path / "prediction"
    shutil.copytree(demo_run / "prediction", prediction)
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    review = tmp_path / "review.gpkg"
    done = run_cli("review", str(prediction), "--gpkg", str(review))
    chains = graph_boundaries(graph)
    assert done.returncode == 0 and f"({graph.n_edges} edges;" in done.stdout, done.stderr
    assert sorted(name for name, _ in pyogrio.list_layers(review)) == ["boundaries", "complete", "held_back"]
    draft, held = (
        pyogrio.read_dataframe(review, layer=name, read_geometry=False) for name in ("boundaries", "held_back")
    )
    assert len(draft) + len(held) == len(chains) and f"{len(draft)} boundaries to review" in done.stdout
    assert (np.diff(draft["confidence"].to_numpy()) >= 0).all()  # the least sure first
    ids = sorted(int(k) for value in list(draft["edge_ids"]) + list(held["edge_ids"]) for k in value.split(";"))
    assert ids == list(range(graph.n_edges))  # every edge in exactly one boundary
    complete = pyogrio.read_info(review, layer="complete")
    assert complete["features"] == 0 and complete["geometry_type"] == "Polygon" and complete["crs"] == "EPSG:32618"
    done = run_cli("apply-review", str(prediction), str(review))
    assert (
        done.returncode == 0
        and "0 deleted, 0 accepted, 0 vertices moved, 0 added, 0 areas marked complete" in done.stdout
    )
    after = BoundaryGraph.read_json(prediction / "graph.json")
    assert np.array_equal(after.vertices, graph.vertices) and np.array_equal(after.edges, graph.edges)
    own = run_cli("review", str(prediction), "--gpkg", str(prediction / "boundaries.gpkg"))
    assert own.returncode == 2 and own.stderr.strip() == (
        f"error: {prediction / 'boundaries.gpkg'}: is the prediction's own "
        "GeoPackage, which apply-review rewrites: give another file"
    )
    empty = tmp_path / "empty"
    empty.mkdir()
    done = run_cli("review", str(empty), "--gpkg", str(tmp_path / "x.gpkg"))
    assert done.returncode == 2 and "not a finished prediction" in done.stderr and not (tmp_path / "x.gpkg").exists()
    district = run_cli("review", str(prediction), "--gpkg", str(tmp_path / "d.gpkg"), "--bounds", "0,0,1,1")
    assert (
        district.returncode == 2
        and "--gpkg writes the whole city's" in district.stderr
        and not (tmp_path / "d.gpkg").exists()
    )


def test_boundary_layers_edited_in_a_gis_give_the_page_s_graph(two_predictions, tmp_path):
    """In the layers review --gpkg writes, a reviewer deletes a boundary, splits one and deletes a
    part, drags the start of a third, draws a line and marks the whole city complete. The page's
    equivalent edits (the boundaries' edges deleted, the kept part drawn, the vertex moved, the
    line added, the area) give the same graph and record; held-back boundaries nobody touched
    inside the area go in both."""
    import json

    from csboundary.graph.boundaries import graph_boundaries

    page, gis = two_predictions
    graph = BoundaryGraph.read_json(page / "graph.json")
    review = tmp_path / "review.gpkg"
    assert run_cli("review", str(gis), "--gpkg", str(review)).returncode == 0
    layer = gpd.read_file(review, layer="boundaries")
    chains = {tuple(sorted(b.edges.tolist())): b for b in graph_boundaries(graph)}
    ids = [[int(k) for k in value.split(";")] for value in layer["edge_ids"]]
    gone = 0
    split = next(i for i, e in enumerate(ids) if i != gone and len(e) >= 3)
    touches = lambda i, j: bool(set(graph.edges[ids[i]].ravel()) & set(graph.edges[ids[j]].ravel()))  # noqa: E731
    moved = next(
        i for i in range(len(ids)) if i not in (gone, split) and not touches(i, split) and not touches(i, gone)
    )
    coords = {i: np.asarray(line.coords)[:, :2] for i, line in enumerate(layer.geometry)}
    part = coords[split][: len(coords[split]) // 2 + 1]
    start = chains[tuple(sorted(ids[moved]))]
    start_vertex = int(
        next(v for v in graph.edges[start.edges[0]] if np.allclose(graph.vertices[v], start.polyline[0]))
    )
    new_start = coords[moved][0] + np.array([0.5, -0.4])
    drawn = world(graph, np.array([[500.0, 500.0], [540.0, 520.0], [600.0, 520.0]]))
    w, h = json.loads((gis / "summary.json").read_text())["mosaic_px"]
    corners = world(graph, np.array([[-5.0, -5.0], [w + 5.0, -5.0], [w + 5.0, h + 5.0], [-5.0, h + 5.0], [-5.0, -5.0]]))

    rows = layer.drop(index=[gone]).copy()
    geometry = {i: LineString(c) for i, c in coords.items()}
    geometry[split] = LineString(part)
    geometry[moved] = LineString(np.concatenate([new_start[None], coords[moved][1:]]))
    rows = rows.set_geometry(gpd.GeoSeries([geometry[i] for i in rows.index], index=rows.index, crs=layer.crs))
    blank = {c: None for c in rows.columns if c != "geometry"}
    rows = gpd.GeoDataFrame(
        list(rows.to_dict("records")) + [{**blank, "geometry": LineString(drawn)}], geometry="geometry", crs=layer.crs
    )
    rows.to_file(review, layer="boundaries", driver="GPKG", engine="pyogrio")
    gpd.GeoDataFrame({"note": ["all"]}, geometry=[Polygon(corners)], crs=layer.crs).to_file(
        review, layer="complete", driver="GPKG", engine="pyogrio"
    )
    done = run_cli("apply-review", str(gis), str(review))
    assert done.returncode == 0, done.stderr

    def line_feature(action, coordinates, **props):
        return {
            "type": "Feature",
            "properties": {"action": action, **props},
            "geometry": {"type": "LineString", "coordinates": np.asarray(coordinates).tolist()},
        }

    features = [line_feature("delete", world_line(graph, k), edge=k) for k in sorted(ids[gone] + ids[split])]
    features += [
        {
            "type": "Feature",
            "properties": {"action": "move", "vertex": start_vertex},
            "geometry": {"type": "Point", "coordinates": new_start.tolist()},
        },
        line_feature("add", part),
        line_feature("add", drawn),
        {
            "type": "Feature",
            "properties": {"action": "complete"},
            "geometry": {"type": "Polygon", "coordinates": [corners.tolist()]},
        },
    ]
    done = run_cli("apply-review", str(page), str(edits_file(tmp_path / "edits.geojson", page, features)))
    assert done.returncode == 0, done.stderr

    a, b = BoundaryGraph.read_json(page / "graph.json"), BoundaryGraph.read_json(gis / "graph.json")
    assert a.n_edges == b.n_edges and a.n_vertices == b.n_vertices and (a.edges == b.edges).all()
    assert np.allclose(a.vertices, b.vertices, atol=1e-6)
    page_record, gis_record = (json.loads((p / "review.json").read_text())["reviews"][-1] for p in (page, gis))
    for key in ("deleted_edges", "moved_vertices", "added_edges", "held_back_deleted"):
        assert sorted(page_record[key]) == sorted(gis_record[key]), key
    held = gpd.read_file(review, layer="held_back")
    held_edges = sorted(int(k) for value in held["edge_ids"] for k in value.split(";"))
    assert (
        sorted(gis_record["held_back_deleted"]) == held_edges
    )  # all of the city is complete: every untouched held-back edge goes
