"""One image, one answer: ``predict-patch`` on an image of at most 1100 px writes the graph.json
that ``predict`` writes for it (the shipped weights, so noding, fragment dropping, end attachment
and the other city-graph steps all have work to do)."""

from __future__ import annotations

import json

import pytest
import rasterio
from rasterio.windows import Window
from typer.testing import CliRunner

from csboundary.cli.main import app
from csboundary.data import city_layout
from csboundary.data.geotiff import write_geotiff
from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig
from csboundary.pipeline.jobs.predict import predict_patch_to_folder, predict_to_folder
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.patch import load_predictor


@pytest.fixture(scope="module")
def tile(tmp_path_factory):
    """One 1100 x 1100 px test-split tile at the shipped model's 0.152 m."""
    out = tmp_path_factory.mktemp("one-tile") / "city"
    synthesize_city(out, seed=3, split="test", tiles=(1, 1), config=SynthConfig(tile_size=1100), progress=False)
    return next(city_layout.tiles_dir(out).glob("*.tif"))


@pytest.fixture(scope="module")
def predictor():
    return load_predictor(None, "cpu")


def top_left(tile, path, width: int, height: int):
    """The ``width x height`` px part of ``tile`` at its top right (where its streets cross) as a
    GeoTIFF of its own."""
    with rasterio.open(tile) as src:
        window = Window(src.width - width, 0, width, height)
        return write_geotiff(path, src.read(window=window), src.window_transform(window), src.crs.to_string())


def graph_json(folder) -> dict:
    return json.loads((folder / "graph.json").read_text())


# 700: one window; 1050 x 700 and 1100: the grid's 1000 px cores make two and four windows
@pytest.mark.parametrize("width, height", [(700, 700), (1050, 700), (1100, 1100)])
def test_predict_patch_writes_the_graph_predict_writes(tile, predictor, tmp_path, width, height):
    image = top_left(tile, tmp_path / f"image-{width}x{height}.tif", width, height)
    predict_to_folder([image], tmp_path / "predict", predictor, PredictionOptions(progress=False))
    predict_patch_to_folder(image, tmp_path / "patch", predictor)
    assert len(graph_json(tmp_path / "predict")["edges"]) > 10  # a graph worth comparing
    # vertices, edges, kinds, scores, polylines, patches, georeference
    assert graph_json(tmp_path / "patch") == graph_json(tmp_path / "predict")
    assert {p.name for p in (tmp_path / "patch").iterdir()} == {"graph.json", "boundaries.geojson", "overlay.png"}


def test_the_two_commands_take_the_city_graph_settings_alike(tile, predictor, tmp_path):
    image = top_left(tile, tmp_path / "image.tif", 700, 700)
    default = predict_patch_to_folder(image, tmp_path / "default", predictor)
    options = ["--device", "cpu", "--min-fragment-length", "800", "--attach-ends", "0"]
    for command in ("predict-patch", "predict"):
        result = CliRunner().invoke(app, [command, str(image), "--out", str(tmp_path / command), *options])
        assert result.exit_code == 0, result.output
    assert graph_json(tmp_path / "predict-patch") == graph_json(tmp_path / "predict")
    assert 0 < len(graph_json(tmp_path / "predict")["edges"]) < default.n_edges  # the settings took effect
