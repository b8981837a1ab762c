"""``csboundary evaluate`` as a user meets it: a city directory, graph JSON, pixel GeoJSON, errors."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from csboundary.data import city_layout
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.metrics.io import load_pair
from helpers import run_cli

run = run_cli


@pytest.fixture(scope="module")
def city(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("evaluate") / "city"
    result = run(
        "synth",
        str(out),
        "--seed",
        "4",
        "--tiles",
        "1x2",
        "--tile-size",
        "400",
        "--gsd",
        "0.5",
        "--split",
        "test",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    return out


@pytest.fixture(scope="module")
def broken_prediction(city, tmp_path_factory) -> Path:
    """The ground truth in the city's pixel frame with every 7th edge cut out, as graph JSON."""
    _, gt, _ = load_pair(city_layout.ground_truth_path(city), city)
    keep = np.arange(gt.n_edges) % 7 != 3
    pred = BoundaryGraph(gt.vertices, gt.edges[keep], transform=gt.transform, crs=gt.crs)
    return pred.write_json(tmp_path_factory.mktemp("pred") / "pred.json")


def error_line(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, (result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def test_help_lists_evaluate():
    result = run("--help")
    assert result.returncode == 0 and "evaluate" in result.stdout


def test_ground_truth_against_its_city_scores_one(city, tmp_path):
    out = tmp_path / "scores.json"
    result = run("evaluate", str(city_layout.ground_truth_path(city)), str(city), "--json", str(out))
    assert result.returncode == 0, result.stderr
    assert "APLS" in result.stdout and "TLTS" in result.stdout and "tau=2" in result.stdout
    data = json.loads(out.read_text())
    assert data["scale"] == "city" and data["apls_variant"] == "paper"
    assert all(data["metrics"][k] == pytest.approx(1.0) for k in ("precision@2", "recall@2", "f1@10", "apls", "tlts"))
    assert data["counts"]["pairs"] > 0


def test_graph_json_prediction_at_patch_scale_is_seeded(city, broken_prediction, tmp_path):
    outs = []
    for name in ("a.json", "b.json"):
        out = tmp_path / name
        result = run(
            "evaluate",
            str(broken_prediction),
            str(city),
            "--scale",
            "patch",
            "--apls",
            "symmetric",
            "--seed",
            "3",
            "--json",
            str(out),
        )
        assert result.returncode == 0, result.stderr
        outs.append(json.loads(out.read_text()))
    assert outs[0] == outs[1]
    m = outs[0]["metrics"]
    assert m["precision@2"] == pytest.approx(1.0) and m["recall@2"] < 1.0
    assert 0 < m["apls"] < 1 and 0 <= m["tlts"] < 1 and outs[0]["patches"]


def test_pixel_geojson_needs_and_honours_pixels_flag(tmp_path):
    def geojson(path: Path, rows: list[float]) -> Path:
        features = [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "LineString", "coordinates": [[10.5, r], [110.5, r]]},
            }
            for r in rows
        ]
        path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
        return path

    gt = geojson(tmp_path / "gt.geojson", [10.5, 50.5])
    pred = geojson(tmp_path / "pred.geojson", [13.5, 53.5])  # 3 px lower: P = R = 0 at tau 2, 1 at tau 5
    out = tmp_path / "s.json"
    result = run("evaluate", str(pred), str(gt), "--pixels", "--json", str(out))
    assert result.returncode == 0, result.stderr
    m = json.loads(out.read_text())["metrics"]
    assert (m["precision@2"], m["recall@2"], m["precision@5"], m["recall@5"]) == (0.0, 0.0, 1.0, 1.0)
    # GeoJSON without a crs member is WGS 84 by definition: pixels must be declared
    assert "--pixels" in error_line(run("evaluate", str(pred), str(gt)))
    # pixels beyond any latitude, read as degrees, are refused in one line instead of scoring 0
    far = geojson(tmp_path / "far.geojson", [500.5])
    line = error_line(run("evaluate", str(far), str(gt)))
    assert "far.geojson" in line and "out of range" in line and "--pixels" in line
    assert run("evaluate", str(far), str(geojson(tmp_path / "gt2.geojson", [500.5])), "--pixels").returncode == 0


def test_missing_file_is_one_line_naming_it(city, tmp_path):
    missing = tmp_path / "nope.gpkg"
    line = error_line(run("evaluate", str(missing), str(city)))
    assert str(missing) in line and "file not found" in line


def test_bad_inputs_raise_input_error_naming_the_file(city, broken_prediction, tmp_path):
    # the same loader the command uses; main() prints these as one `error:` line with exit 2
    not_graph = tmp_path / "other.json"
    not_graph.write_text('{"hello": 1}')
    with pytest.raises(InputError, match="neither a csboundary-graph") as err:
        load_pair(not_graph, city)
    assert err.value.path == str(not_graph)

    far = BoundaryGraph.read_json(broken_prediction)
    far = BoundaryGraph(far.vertices + 1e6, far.edges, transform=far.transform, crs=far.crs).write_json(
        tmp_path / "far.json"
    )
    with pytest.raises(InputError, match="outside the raster") as err:
        load_pair(far, city)
    assert err.value.path == str(far)
    with pytest.raises(InputError, match="does not overlap") as err:
        load_pair(far, city_layout.ground_truth_path(city), gsd=0.5)
    assert err.value.path == str(far)
    with pytest.raises(InputError, match="--raster or --gsd"):
        load_pair(city_layout.ground_truth_path(city), city_layout.ground_truth_path(city))


def test_wrong_option_value_is_refused(city, broken_prediction):
    result = run("evaluate", str(broken_prediction), str(city), "--apls", "sideways")
    assert result.returncode == 2 and "--apls" in result.stderr
