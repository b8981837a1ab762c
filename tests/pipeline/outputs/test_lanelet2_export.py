"""Lanelet2 export: the map loads with lanelet2.io.load, has one road_border linestring per
boundary of the GeoPackage, and its geometry matches the GeoPackage within 1 cm after projection."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pytest

lanelet2 = pytest.importorskip("lanelet2")

from csboundary.graph import BoundaryGraph  # noqa: E402
from csboundary.pipeline.outputs.lanelet2_export import local_xy, projector_for, read_origin, to_wgs84, write_lanelet2  # noqa: E402
from helpers import run_cli  # noqa: E402


@pytest.fixture(scope="module")
def demo(demo_run, tmp_path_factory):
    """The demo city predicted by the shipped model, with --lanelet2."""
    pred = tmp_path_factory.mktemp("l2") / "pred"
    done = run_cli(
        "predict", str(demo_run / "city"), "--out", str(pred), "--lanelet2", "--device", "cpu", "--quiet", timeout=600
    )
    assert done.returncode == 0, done.stderr
    return pred


def test_the_demo_city_round_trips_through_lanelet2(demo):
    info = demo / "map_projector_info.yaml"
    projector = projector_for(read_origin(info))
    loaded = lanelet2.io.load(str(demo / "map.osm"), projector)
    borders = {
        int(ls.attributes["boundary_id"]): ls for ls in loaded.lineStringLayer if ls.attributes["type"] == "road_border"
    }
    frame = gpd.read_file(demo / "boundaries.gpkg", layer="road_boundaries")
    assert len(frame) > 10 and set(borders) == set(frame["boundary_id"])
    to_lonlat = to_wgs84(str(frame.crs))
    worst, closed = 0.0, 0
    for row in frame.itertuples():
        coords = np.asarray(row.geometry.coords)[:, :2]
        expected = local_xy(projector, *to_lonlat(coords[:, 0], coords[:, 1]))
        line = borders[row.boundary_id]
        got = np.array([(p.x, p.y) for p in line])
        assert got.shape == expected.shape
        worst = max(worst, float(np.abs(got - expected).max()))
        if np.allclose(coords[0], coords[-1], rtol=0, atol=1e-9):
            closed += 1
            assert line[0].id == line[len(line) - 1].id  # a loop is a closed linestring, not two points that coincide
        assert float(line.attributes["confidence"]) == pytest.approx(row.confidence_mean, abs=1e-4)
    assert worst < 0.01  # metres


def test_a_closed_boundary_is_a_closed_linestring(tmp_path):
    # a traffic island: four vertices joined in a ring, in UTM metres
    from rasterio.transform import Affine

    ring = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 30.0], [0.0, 30.0]])
    graph = BoundaryGraph(ring, [[0, 1], [1, 2], [2, 3], [3, 0]])
    graph.transform, graph.crs = Affine(0.5, 0, 583000.0, 0, -0.5, 4507000.0), "EPSG:32618"
    write_lanelet2(graph, tmp_path / "m.osm")
    projector = projector_for(read_origin(tmp_path / "map_projector_info.yaml"))
    borders = [
        ls
        for ls in lanelet2.io.load(str(tmp_path / "m.osm"), projector).lineStringLayer
        if ls.attributes["type"] == "road_border"
    ]
    assert len(borders) == 1
    line = borders[0]
    assert (
        len(line) == 5 and line[0].id == line[len(line) - 1].id
    )  # closed by its first point, not by a second point on top of it


def test_export_lanelet2_writes_the_same_map_from_a_prediction_folder(demo, tmp_path):
    out = tmp_path / "again.osm"
    done = run_cli("export-lanelet2", str(demo), "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert out.read_text() == (demo / "map.osm").read_text()  # same origin, same ids


def test_a_map_without_crs_is_refused(tmp_path):
    graph = BoundaryGraph(np.array([[0.0, 0.0], [10.0, 0.0]]), [[0, 1]])
    from rasterio.transform import Affine

    graph.transform = Affine.identity()
    with pytest.raises(Exception, match="needs georeferenced"):
        write_lanelet2(graph, tmp_path / "m.osm")
    assert not (tmp_path / "m.osm").exists()


def test_an_origin_far_from_the_boundaries_is_one_line(demo, tmp_path):
    done = run_cli("export-lanelet2", str(demo), "--out", str(tmp_path / "far.osm"), "--origin", "-40.7,106.0")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "too far from the origin" in lines[0]
    assert not (tmp_path / "far.osm").exists()


def test_a_graph_with_a_nan_vertex_is_one_line(demo, tmp_path):
    graph = BoundaryGraph.read_json(demo / "graph.json")
    graph.vertices[0] = np.nan
    graph.write_json(tmp_path / "graph.json")
    done = run_cli("export-lanelet2", str(tmp_path / "graph.json"), "--out", str(tmp_path / "m.osm"))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "graph.json" in lines[0] and "not a finite number" in lines[0]
    assert not (tmp_path / "m.osm").exists()


def test_export_lanelet2_of_a_district(demo, tmp_path):
    frame = gpd.read_file(demo / "boundaries.gpkg", layer="road_boundaries")
    x0, y0, x1, y1 = frame.total_bounds
    west = (x0, y0, (x0 + x1) / 2, y1)
    done = run_cli(
        "export-lanelet2", str(demo), "--out", str(tmp_path / "west.osm"), "--bounds", ",".join(map(str, west))
    )
    assert done.returncode == 0, done.stderr
    projector = projector_for(read_origin(tmp_path / "map_projector_info.yaml"))
    borders = [
        ls
        for ls in lanelet2.io.load(str(tmp_path / "west.osm"), projector).lineStringLayer
        if ls.attributes["type"] == "road_border"
    ]
    # the map holds exactly the edges meeting the district, merged into boundaries of their own
    from shapely.geometry import box

    edges = gpd.read_file(demo / "boundaries.gpkg", layer="edges")
    meeting = edges[edges.intersects(box(*west))]
    assert 0 < len(meeting) < len(edges) and len(borders) > 0
    assert sum(float(ls.attributes["length_m"]) for ls in borders) == pytest.approx(meeting["length_m"].sum(), rel=1e-3)
    done = run_cli("export-lanelet2", str(demo), "--out", str(tmp_path / "bad.osm"), "--bounds", "5,5,1,1")
    assert done.returncode != 0 and "MINX < MAXX" in done.stderr


@pytest.mark.parametrize("where", ["beside", "degrees"])
def test_bounds_outside_the_prediction_are_one_line_and_no_map(demo, tmp_path, where):
    frame = gpd.read_file(demo / "boundaries.gpkg", layer="edges")
    x0, y0, x1, y1 = frame.total_bounds
    # a district east of the city, or the city's own corner given in degrees on its metric CRS
    bounds = (x1 + 5000, y0, x1 + 6000, y1) if where == "beside" else (-74.01, 40.70, -74.00, 40.71)
    done = run_cli(
        "export-lanelet2", str(demo), "--out", str(tmp_path / "m.osm"), "--bounds", ",".join(map(str, bounds))
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "lies outside the prediction" in lines[0], done.stderr
    assert not (tmp_path / "m.osm").exists() and not (tmp_path / "map_projector_info.yaml").exists()


def test_min_confidence_leaves_out_the_doubtful_edges(demo, tmp_path):
    edges = gpd.read_file(demo / "boundaries.gpkg", layer="edges")
    cut = float(np.median(edges["confidence"]))
    done = run_cli("export-lanelet2", str(demo), "--out", str(tmp_path / "sure.osm"), "--min-confidence", str(cut))
    assert done.returncode == 0, done.stderr
    kept = edges[edges["confidence"] >= cut]
    assert f"{len(kept)} of {len(edges)} edges kept" in done.stdout
    projector = projector_for(read_origin(tmp_path / "map_projector_info.yaml"))
    borders = [
        ls
        for ls in lanelet2.io.load(str(tmp_path / "sure.osm"), projector).lineStringLayer
        if ls.attributes["type"] == "road_border"
    ]
    assert sum(float(ls.attributes["length_m"]) for ls in borders) == pytest.approx(kept["length_m"].sum(), rel=1e-3)
    assert min(float(ls.attributes["confidence_min"]) for ls in borders) >= cut - 1e-4
