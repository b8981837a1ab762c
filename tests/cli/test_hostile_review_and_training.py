"""Hostile inputs of the commands that review and learn (issue 65): layers a GIS mangled, two runs
into one folder, empty arguments from Python, imagery with nothing in it, a prediction folder
given to evaluate. Each case runs as a user does and asserts the one ``error:`` line and that
nothing was changed or left behind."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import geopandas as gpd
import numpy as np
import pytest
from affine import Affine
from shapely.geometry import Polygon

from csboundary.data.folder_lock import folder_lock
from csboundary.data.geotiff import write_geotiff
from csboundary.errors import InputError
from helpers import run_cli


def one_error(result, *needles: str) -> str:
    lines = [
        line for line in result.stderr.strip().splitlines() if not line.startswith("warning: ")
    ]  # RGB input says so
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def prediction(demo_run, tmp_path) -> Path:
    pred = tmp_path / "pred"
    shutil.copytree(demo_run / "prediction", pred)
    return pred


def edited_copy(prediction: Path, path: Path, change) -> Path:
    """A copy of the prediction's GeoPackage whose edges layer ``change`` rewrote."""
    shutil.copy(prediction / "boundaries.gpkg", path)
    edges = gpd.read_file(path, layer="edges")
    change(edges).to_file(path, layer="edges", driver="GPKG", engine="pyogrio")
    return path


def unchanged(prediction: Path, before: bytes) -> bool:
    return (prediction / "graph.json").read_bytes() == before and not (prediction / "review.json").exists()


@pytest.mark.parametrize(
    "value, phrase", [("abc", "edge_id 'abc' is not a whole number"), ("inf", "edge_id 'inf' is not a whole number")]
)
def test_an_edge_id_that_is_not_a_number_is_one_line(prediction, tmp_path, value, phrase):
    before = (prediction / "graph.json").read_bytes()

    def change(edges):
        edges["edge_id"] = edges["edge_id"].astype(str)
        edges.loc[0, "edge_id"] = value
        return edges

    edited = edited_copy(prediction, tmp_path / "e.gpkg", change)
    one_error(
        run_cli("apply-review", str(prediction), str(edited)), str(edited), "feature 0 of its edges layer", phrase
    )
    assert unchanged(prediction, before)


def test_an_emptied_layer_does_not_delete_the_whole_map(prediction, tmp_path):
    before = (prediction / "graph.json").read_bytes()
    edited = edited_copy(prediction, tmp_path / "e.gpkg", lambda edges: edges.iloc[:0])
    one_error(run_cli("apply-review", str(prediction), str(edited)), "holds no feature", "would delete all")
    assert unchanged(prediction, before)
    review = tmp_path / "review.gpkg"
    assert run_cli("review", str(prediction), "--gpkg", str(review)).returncode == 0
    for layer in ("boundaries", "held_back"):
        rows = gpd.read_file(review, layer=layer)
        rows.iloc[:0].to_file(review, layer=layer, driver="GPKG", engine="pyogrio")
    one_error(run_cli("apply-review", str(prediction), str(review)), "its boundaries, held_back layers hold no feature")
    assert unchanged(prediction, before)


def test_an_empty_polygon_marked_complete_is_one_line(prediction, tmp_path):
    before = (prediction / "graph.json").read_bytes()
    review = tmp_path / "review.gpkg"
    assert run_cli("review", str(prediction), "--gpkg", str(review)).returncode == 0
    crs = gpd.read_file(review, layer="boundaries").crs
    gpd.GeoDataFrame({"note": ["x"]}, geometry=[Polygon()], crs=crs).to_file(
        review, layer="complete", driver="GPKG", engine="pyogrio"
    )
    one_error(
        run_cli("apply-review", str(prediction), str(review)), "feature 0 of its complete layer is an empty polygon"
    )
    assert unchanged(prediction, before)


def test_two_reviews_applied_at_once_never_lose_one(prediction, tmp_path):
    """While one apply-review holds the prediction, a second is refused instead of overwriting its
    edits; run afterwards, it applies on top of them."""
    graph = json.loads((prediction / "graph.json").read_text())
    review = tmp_path / "review.gpkg"
    assert run_cli("review", str(prediction), "--gpkg", str(review)).returncode == 0
    before = (prediction / "graph.json").read_bytes()
    with folder_lock(prediction):  # as a first apply-review does while it works
        one_error(run_cli("apply-review", str(prediction), str(review)), "in use by another csboundary run")
    assert unchanged(prediction, before)
    done = run_cli("apply-review", str(prediction), str(review))
    assert done.returncode == 0, done.stderr
    assert len(json.loads((prediction / "graph.json").read_text())["edges"]) == len(graph["edges"])


def test_evaluate_takes_a_prediction_folder(demo_run):
    pred = demo_run / "prediction"
    city = demo_run / "city"
    folder, file = run_cli("evaluate", str(pred), str(city)), run_cli("evaluate", str(pred / "graph.json"), str(city))
    assert folder.returncode == 0 == file.returncode, folder.stderr
    assert folder.stdout.splitlines()[1:] == file.stdout.splitlines()[1:]  # the first line names the input as given
    one_error(run_cli("evaluate", str(demo_run), str(city)), "neither a city directory", "nor a prediction folder")


def test_training_from_python_with_nothing_to_learn_from_is_refused(tmp_path):
    import csboundary

    with pytest.raises(InputError, match="no labelled cities given"):
        csboundary.finetune([], tmp_path / "tuned.pt")
    with pytest.raises(InputError, match="no imagery given"):
        csboundary.adapt([], tmp_path / "adapted.pt")
    assert not any(tmp_path.iterdir())  # no work folder left


def _geotiff(path: Path, size: int, fill=None) -> Path:
    rng = np.random.default_rng(0)
    data = (
        rng.integers(0, 200, (3, size, size)).astype(np.uint8)
        if fill is None
        else np.full((3, size, size), fill, np.uint8)
    )
    valid = np.zeros((size, size), bool) if fill == 0 else None  # all no-data: its mask says so
    return write_geotiff(path, data, Affine(0.152, 0, 500000, 0, -0.152, 4400000), "EPSG:32618", valid=valid)


def test_a_work_folder_that_is_a_file_or_in_use_is_one_line(tmp_path):
    image = _geotiff(tmp_path / "a.tif", 700)
    (tmp_path / "notes.txt").write_text("x")
    one_error(
        run_cli("adapt", str(image), "--out", str(tmp_path / "a.pt"), "--work", str(tmp_path / "notes.txt")),
        "notes.txt",
        "is a file: it must be a folder (give --work another path)",
    )
    work = tmp_path / "work"
    work.mkdir()
    with folder_lock(work):  # another adapt or finetune working there
        one_error(
            run_cli("adapt", str(image), "--out", str(tmp_path / "a.pt"), "--work", str(work)),
            "in use by another csboundary run",
        )
        one_error(
            run_cli("finetune", str(tmp_path), "--out", str(tmp_path / "t.pt"), "--work", str(work)),
            "in use by another csboundary run",
        )
    assert not (tmp_path / "a.pt").exists() and not (tmp_path / "t.pt").exists()


def test_imagery_that_is_all_no_data_is_refused_before_any_work(tmp_path):
    empty = _geotiff(tmp_path / "empty.tif", 800, fill=0)
    result = run_cli("adapt", str(empty), "--out", str(tmp_path / "a.pt"), "--device", "cpu")
    one_error(result, "empty.tif", "held no valid pixel")
    assert not (tmp_path / "a.pt").exists() and not (tmp_path / "a-adapt").exists()


@pytest.mark.parametrize(
    "values, phrase",
    [
        ({"edge_threshold": float("nan")}, "--edge-threshold: must be a finite number"),
        ({"min_confidence": float("nan")}, "--min-confidence: must be a finite number"),
        ({"edge_threshold": 5.0}, "--edge-threshold: must be from 0 to 1, got 5"),
        ({"max_degree": -3}, "--max-degree: must be a whole number >= 0"),
    ],
)
def test_graph_settings_from_python_are_checked_as_on_the_command_line(values, phrase):
    """NaN once dropped every decoded edge (or kept none) without a word; the ranges are
    GraphOverrides' own, so the API and the command line refuse the same values."""
    import csboundary

    with pytest.raises(InputError, match=phrase.replace("(", r"\(")):
        csboundary.GraphOverrides(**values)
    assert csboundary.GraphOverrides(edge_threshold=0.3, max_degree=0).edge_threshold == 0.3


def test_predict_from_python_with_a_name_for_a_model_is_one_line(tmp_path):
    import csboundary

    with pytest.raises(InputError, match="notamodel: is not a loaded model"):
        csboundary.predict(tmp_path / "x.tif", tmp_path / "out", model="notamodel")
    assert not (tmp_path / "out").exists()


def test_read_prediction_of_a_file_that_is_not_one_names_it(tmp_path):
    """It named boundaries.gpkg beside the file, a file nobody gave."""
    import csboundary

    tif = _geotiff(tmp_path / "x.tif", 100)
    with pytest.raises(
        InputError, match=r"x\.tif: not a prediction: give its folder, its graph\.json or its boundaries\.gpkg"
    ):
        csboundary.read_prediction(tif)


def test_an_interrupted_command_says_what_it_keeps(tmp_path):
    """Ctrl-C in any command spoke of "a predict run"; a command that keeps nothing says so."""
    import signal
    import subprocess
    import sys
    import time

    run = subprocess.Popen(
        [sys.executable, "-m", "csboundary", "synth", str(tmp_path / "city"), "--tiles", "2x2", "--tile-size", "3000"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(4)  # past the imports, rendering
    run.send_signal(signal.SIGINT)
    _, err = run.communicate(timeout=120)
    last = err.strip().splitlines()[-1]
    assert run.returncode == 130 and last.startswith("interrupted (SIGINT)"), err
    assert "predict" not in last and "run the command again" in last


def test_export_lanelet2_never_filters_raw_network_scores(tmp_path):
    """A bundle without an edge confidence leaves the networks' scores on the edges; predict
    refuses --min-confidence there, and export-lanelet2 now does too (it filtered on them)."""
    from test_hostile_inputs import image, tiny_bundle

    bundle, tif = tiny_bundle(tmp_path / "bundle.pt"), image(tmp_path / "ok.tif")
    done = run_cli(
        "predict",
        str(tif),
        "--out",
        str(tmp_path / "pred"),
        "--weights",
        str(bundle),
        "--quiet",
        "--device",
        "cpu",
        "--engine",
        "torch",
        "--edge-threshold",
        "0.0",
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "pred" / "summary.json").read_text())["settings"]["edge_confidence"] is False
    one_error(
        run_cli(
            "export-lanelet2", str(tmp_path / "pred"), "--out", str(tmp_path / "map.osm"), "--min-confidence", "0.5"
        ),
        "predicted with weights that have no edge confidence",
    )
    assert not (tmp_path / "map.osm").exists()


def test_a_step_count_no_one_means_is_refused(tmp_path):
    """adapt --fpn-steps 1000000000 started a run of about 2.4 million hours without a word."""
    image = _geotiff(tmp_path / "a.tif", 300)
    one_error(
        run_cli("adapt", str(image), "--out", str(tmp_path / "a.pt"), "--fpn-steps", "1000000000"),
        "--fpn-steps: must be a whole number from 1 to 1,000,000, got 1000000000",
    )
    assert not (tmp_path / "a.pt").exists() and not (tmp_path / "a-adapt").exists()


@pytest.mark.parametrize(
    "args, name, kind",
    [(["qgis-plugin", "--out"], "notes.zip", "a zip"), (["adapt", "IMAGE", "--out"], "notes.pt", "a weights bundle")],
)
def test_an_output_name_that_holds_something_else_is_never_overwritten(tmp_path, args, name, kind):
    image = _geotiff(tmp_path / "a.tif", 300)
    target = tmp_path / name
    target.write_text("my notes")
    command = [str(image) if a == "IMAGE" else a for a in args] + [str(target)]
    one_error(run_cli(*command), name, f"exists and is not {kind}")
    assert target.read_text() == "my notes"
