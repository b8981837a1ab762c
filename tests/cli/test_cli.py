"""The command line as a user meets it: exit codes, one-line errors, files it writes."""

from __future__ import annotations

from pathlib import Path

import pytest

from csboundary.data import city_layout
from helpers import run_cli

run = run_cli


@pytest.fixture(scope="module")
def small_city(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "city"
    result = run(
        "synth",
        str(out),
        "--seed",
        "2",
        "--tiles",
        "1x2",
        "--tile-size",
        "400",
        "--gsd",
        "0.5",
        "--split",
        "valid",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    return out


def test_every_command_has_help():
    """Every registered command (found from the app, not listed by hand) answers --help with its
    usage and the first words of its docstring."""
    import typer
    from typer.testing import CliRunner

    from csboundary.cli.main import app

    group = typer.main.get_command(app)
    commands = group.list_commands(None)
    assert len(commands) >= 18 and {"predict", "review", "apply-review", "export-lanelet2", "evaluate"} <= set(commands)
    runner = CliRunner()
    for name in commands:
        result = runner.invoke(app, [name, "--help"])
        summary = " ".join(group.get_command(None, name).help.split()[:3])
        assert result.exit_code == 0 and "Usage" in result.output, name
        assert summary in " ".join(result.output.split()), (name, summary)


def test_synth_writes_a_city(small_city):
    meta = city_layout.read_meta(small_city)
    assert meta["split"] == "valid" and meta["tile_grid"] == [1, 2]
    assert sorted(p.name for p in city_layout.tiles_dir(small_city).iterdir()) == [
        "tile_r00_c00.tif",
        "tile_r00_c01.tif",
    ]
    assert city_layout.ground_truth_path(small_city).exists()


def test_show_writes_png_of_window(small_city, tmp_path):
    import cv2

    out = tmp_path / "w.png"
    result = run("show", str(small_city), "--window", "350,100,100,80", "--out", str(out))
    assert result.returncode == 0, result.stderr
    image = cv2.imread(str(out))
    assert image.shape == (80, 100, 3)  # a window across the tile border, at full resolution


def test_bad_input_is_one_line_naming_the_file(tmp_path):
    bogus = tmp_path / "not-a-raster.tif"
    bogus.write_text("hello")
    result = run("show", str(bogus), "--out", str(tmp_path / "x.png"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(bogus) in lines[0] and "not a raster" in lines[0]
    assert not (tmp_path / "x.png").exists()


def test_missing_file_is_reported(tmp_path):
    result = run("show", str(tmp_path / "nope.tif"), "--out", str(tmp_path / "x.png"))
    assert result.returncode == 2 and "nope.tif: file not found" in result.stderr


def test_bad_tiles_argument_is_rejected(tmp_path):
    result = run("synth", str(tmp_path / "c"), "--tiles", "two")
    assert result.returncode != 0 and "ROWSxCOLS" in result.stderr
    assert not (tmp_path / "c" / city_layout.META_FILE).exists()


@pytest.mark.parametrize(
    "args",
    [["--patch", "1"], ["--patch", "a,b"], ["--patch", "9,9"], ["--window", "0,0,-5,5"], ["--bounds", "x,1,2,3"]],
)
def test_bad_show_arguments_are_one_line_errors(small_city, tmp_path, args):
    result = run("show", str(small_city), *args, "--out", str(tmp_path / "x.png"))
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and not (tmp_path / "x.png").exists()


def test_a_smaller_rewrite_does_not_keep_old_tiles(tmp_path):
    out = tmp_path / "c"
    assert run("synth", str(out), "--tiles", "1x2", "--tile-size", "200", "--gsd", "1.0", "--quiet").returncode == 0
    assert run("synth", str(out), "--tiles", "1x1", "--tile-size", "200", "--gsd", "1.0", "--quiet").returncode == 0
    assert [p.name for p in city_layout.tiles_dir(out).iterdir()] == ["tile_r00_c00.tif"]


def test_demo_predicts_and_scores_a_city_with_the_shipped_weights(demo_run):
    import json

    scores = json.loads((demo_run / "scores.json").read_text())
    assert scores["patch"]["scale"] == "patch" and scores["patch"]["counts"]["patches_scored"] == 9
    assert scores["city"]["scale"] == "city"
    for scale in ("patch", "city"):
        values = [v for v in scores[scale]["metrics"].values() if v is not None]
        assert values and all(0.0 <= v <= 1.0 for v in values)
        assert scores[scale]["metrics"]["f1@5"] > 0.5  # the shipped weights find most curbs of a test city
    printed = (demo_run.parent / "stdout.txt").read_text()
    assert "patch" in printed and "city" in printed and "km2/h" in printed
    for name in ("overview.png", "detail.png", "boundaries.gpkg", "boundaries.geojson", "graph.json", "summary.json"):
        assert (demo_run / "prediction" / name).stat().st_size > 0
    settings = json.loads((demo_run / "prediction" / "summary.json").read_text())["settings"]
    # the default precision is chosen on this machine: what it chose and why is recorded
    assert settings["engine"] == "onnx" and settings.get("precision", "float32") in ("int8", "float32")
    assert settings["precision_choice"].startswith(settings.get("precision", "float32") + ": its FPN ran in")
