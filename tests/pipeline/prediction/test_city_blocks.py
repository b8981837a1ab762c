"""The city graph made block by block equals the one made in one pass, file for file."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pyogrio
import pytest

from csboundary.data import city_layout
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig
from csboundary.graph import BoundaryGraph
from csboundary.pipeline.evaluation.oracle import OracleModel
from csboundary.pipeline.jobs.prediction_run import run_prediction
from csboundary.pipeline.outputs.prediction_files import EDGES_LAYER
from csboundary.pipeline.outputs.prediction_reader import read_prediction_graph
from csboundary.pipeline.prediction.options import PredictionOptions


@pytest.fixture(scope="module")
def city(tmp_path_factory):
    """A 2x2-tile test-split city of 3000 x 3000 px: 3 x 3 patches, boundaries across every seam."""
    out = tmp_path_factory.mktemp("city")
    synthesize_city(out, seed=5, split="test", tiles=(2, 2), config=SynthConfig(tile_size=1500), progress=False)
    mosaic = Mosaic.open(city_layout.tiles_dir(out))
    lines = list(read_ground_truth(city_layout.ground_truth_path(out), mosaic.crs).geometry)
    yield mosaic, lines
    mosaic.close()


def _files(folder) -> dict[str, object]:
    layers = {
        layer: pyogrio.read_dataframe(folder / "boundaries.gpkg", layer=layer)
        for layer in ("road_boundaries", EDGES_LAYER)
    }
    return {
        "graph.json": hashlib.sha256((folder / "graph.json").read_bytes()).hexdigest(),
        "geojson": hashlib.sha256((folder / "boundaries.geojson").read_bytes()).hexdigest(),
        **{layer: frame.to_wkt().to_csv() for layer, frame in layers.items()},
    }


@pytest.mark.parametrize("block", [1, 2])
def test_blocks_give_the_files_of_one_pass(city, tmp_path, block):
    mosaic, lines = city
    model = OracleModel.from_lines(lines, mosaic)
    model.settings = dataclasses.replace(
        model.settings, min_fragment_px=60.0, attach_px=40.0
    )  # the city steps that reach beyond an edge
    one, _ = run_prediction(
        mosaic, model, tmp_path / "one", PredictionOptions(progress=False, block=block, one_pass=True)
    )
    banded, summary = run_prediction(mosaic, model, tmp_path / "blocks", PredictionOptions(progress=False, block=block))
    assert one.graph.n_edges > 100 and summary["counts"]["boundaries"] > 10
    assert _files(tmp_path / "one") == _files(tmp_path / "blocks")
    # the same edges whatever the block size: only their order may differ
    whole, _ = run_prediction(mosaic, model, tmp_path / "whole", PredictionOptions(progress=False, block=8))
    assert _edge_set(whole.graph) == _edge_set(banded.graph)


def _edge_set(graph: BoundaryGraph) -> set:
    lines = [tuple(map(tuple, np.round(graph.edge_polyline(k), 6).tolist())) for k in range(graph.n_edges)]
    return {min(line, line[::-1]) for line in lines}


def test_the_files_agree_and_read_back(city, tmp_path):
    mosaic, lines = city
    result, summary = run_prediction(
        mosaic, OracleModel.from_lines(lines, mosaic), tmp_path / "run", PredictionOptions(progress=False, block=1)
    )
    folder = tmp_path / "run"
    graph = BoundaryGraph.read_json(folder / "graph.json")
    # graph.json written piece by piece is what the graph's own JSON is
    assert json.loads((folder / "graph.json").read_text()) == json.loads(json.dumps(result.graph.to_dict()))
    assert graph.n_edges == summary["counts"]["edges"] == result.graph.n_edges
    # the GeoPackage holds the same graph: every edge, its ends numbered as in graph.json
    edges = pyogrio.read_dataframe(folder / "boundaries.gpkg", layer=EDGES_LAYER).sort_values("edge_id")
    assert edges["edge_id"].tolist() == list(range(graph.n_edges))
    assert (edges[["u", "v"]].to_numpy() == graph.edges).all()
    # every edge is on exactly one boundary, and boundaries chain through degree-2 vertices only
    boundaries = pyogrio.read_dataframe(folder / "boundaries.gpkg", layer="road_boundaries")
    assert boundaries["n_edges"].sum() == graph.n_edges and len(boundaries) == summary["counts"]["boundaries"]
    assert sorted(edges["boundary_id"].unique()) == list(range(len(boundaries)))
    degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    for _, group in edges.groupby("boundary_id"):
        inner = np.bincount(group[["u", "v"]].to_numpy().ravel(), minlength=graph.n_vertices)
        ends = np.flatnonzero(inner == 1)  # the vertices where the boundary stops (none for a loop)
        assert len(ends) in (0, 2) and all(degree[x] != 2 for x in ends)
    # read back from the GeoPackage alone: the same lines
    back = read_prediction_graph(folder / "boundaries.gpkg")
    assert back.n_edges == graph.n_edges
    assert np.allclose(np.sort(back.vertices, axis=0), np.sort(graph.vertices, axis=0), atol=1e-6)
    # a district: only the edges meeting its box, all of them
    x0, y0, x1, y1 = mosaic.bounds
    box = (x0, y0, (x0 + x1) / 2, (y0 + y1) / 2)
    part = read_prediction_graph(folder, bounds=box)
    from shapely.geometry import box as shapely_box

    inside = [line.intersects(shapely_box(*box)) for line in graph.to_linestrings(world=True)]
    assert 0 < part.n_edges == sum(inside) < graph.n_edges


def test_a_district_of_something_else_is_one_line(tmp_path):
    import geopandas as gpd
    from shapely.geometry import LineString

    from csboundary.errors import InputError

    with pytest.raises(InputError, match="not found"):
        read_prediction_graph(tmp_path / "typo", bounds=(0, 0, 1, 1))
    frame = gpd.GeoDataFrame({"u": [0], "v": [1]}, geometry=[LineString([(0, 0), (1, 1)])], crs="EPSG:32618")
    frame.to_file(tmp_path / "boundaries.gpkg", layer=EDGES_LAYER, engine="pyogrio")
    with pytest.raises(InputError, match="pixel grid"):
        read_prediction_graph(tmp_path, bounds=(0, 0, 1, 1))
