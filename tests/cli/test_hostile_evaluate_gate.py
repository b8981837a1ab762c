"""Hostile inputs of issue 65, part: a ground-truth line thousands of km long evaluated against a
raster (cut to the imagery first: seconds, not minutes and gigabytes; no advice to give the
--raster that was given), and a large --surface-gate (the same decisions at the default's cost).
Each case runs the command line as a user does."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from affine import Affine

from csboundary.data.geotiff import write_geotiff
from helpers import run_cli

UTM = "EPSG:32618"
GSD = 0.3
X0, Y0 = 500000.0, 4400000.0  # top-left corner of the 300 px test image


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A 300 px GeoTIFF, a prediction of two curbs and a ground truth whose second curb runs
    100,000 km away (and the same ground truth cut by hand at the image's border)."""
    import geopandas as gpd
    from shapely.geometry import LineString

    root = tmp_path_factory.mktemp("evaluate_far")
    data = np.random.default_rng(0).integers(0, 200, (4, 300, 300)).astype(np.uint8)
    tif = write_geotiff(root / "image.tif", data, Affine(GSD, 0, X0, 0, -GSD, Y0), UTM)
    curb = LineString([(X0 + 3, Y0 - 30), (X0 + 80, Y0 - 30)])
    pred = [curb, LineString([(X0 + 3, Y0 - 60), (X0 + 80, Y0 - 61)])]
    far = LineString([(X0 + 3, Y0 - 60.5), (X0 + 5e7, Y0 - 60.5), (X0 + 5e7, Y0 + 5e7)])  # 100,000 km
    cut = LineString([(X0 + 3, Y0 - 60.5), (X0 + 90 + 5 * GSD, Y0 - 60.5)])  # what the metrics keep: the image and 5 px
    paths = {"tif": tif, "pred": root / "pred.gpkg", "far": root / "far.gpkg", "cut": root / "cut.gpkg"}
    for name, lines in (("pred", pred), ("far", [curb, far]), ("cut", [curb, cut])):
        gpd.GeoDataFrame(geometry=lines, crs=UTM).to_file(paths[name])
    return paths


def scores(scene, gt: str, *extra: str) -> dict:
    out = scene["tif"].parent / f"{gt}{len(extra)}.json"
    done = run_cli(
        "evaluate",
        str(scene["pred"]),
        str(scene[gt]),
        "--raster",
        str(scene["tif"]),
        "--json",
        str(out),
        *extra,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert "--raster" not in done.stderr
    return json.loads(out.read_text())


@pytest.mark.parametrize("scale", ["city", "patch"])
def test_a_100000_km_ground_truth_line_is_cut_to_the_raster_and_scores_as_its_part_inside(scene, scale):
    far, cut = scores(scene, "far", "--scale", scale), scores(scene, "cut", "--scale", scale)
    assert far["metrics"] == pytest.approx(cut["metrics"], nan_ok=True)
    if scale == "city":
        review = far["review_effort"]
        assert review["true_boundary_km"] == pytest.approx(cut["review_effort"]["true_boundary_km"])
        assert review["true_boundary_km"] < 0.2  # the imagery's boundaries, not the label's 100,000 km


def test_with_a_raster_given_a_refusal_does_not_advise_giving_it(scene, monkeypatch, capsys):
    """Boundaries inside the imagery beyond the metrics' limit (here a limit of 100 px) are
    refused in one line that names the imagery, not one that asks for the --raster given."""
    from csboundary.cli.main import main
    from csboundary.metrics import pixel

    monkeypatch.setattr(pixel, "MAX_RASTER_PIXELS", 100)
    monkeypatch.setattr(
        sys, "argv", ["csboundary", "evaluate", str(scene["pred"]), str(scene["far"]), "--raster", str(scene["tif"])]
    )
    with pytest.raises(SystemExit) as stop:
        main()
    lines = [line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("warning:")]
    assert stop.value.code == 2 and len(lines) == 1 and lines[0].startswith("error: "), lines
    assert "--raster" not in lines[0] and f"within the imagery {scene['tif']}" in lines[0], lines[0]


def test_pixels_of_a_raster_are_cut_to_it(scene, tmp_path):
    """--pixels with --raster: the raster still says where the imagery is, so a label point at
    2e9 px is cut off instead of refused with advice to give the --raster that was given."""
    line = {
        "type": "Feature",
        "properties": {},
        "geometry": {"type": "LineString", "coordinates": [[10, 10], [-500, 2e9]]},
    }
    (tmp_path / "gt.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": [line]}))
    line["geometry"]["coordinates"] = [[10, 10], [10, 250]]
    (tmp_path / "pred.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": [line]}))
    done = run_cli(
        "evaluate",
        str(tmp_path / "pred.geojson"),
        str(tmp_path / "gt.geojson"),
        "--pixels",
        "--raster",
        str(scene["tif"]),
        "--json",
        str(tmp_path / "s.json"),
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "s.json").read_text())["inputs"]["frame"].startswith("pixels of ")


# -- a large surface gate --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def city(tmp_path_factory):
    root = tmp_path_factory.mktemp("gate")
    done = run_cli(
        "synth", str(root / "city"), "--seed", "1", "--tiles", "1x1", "--tile-size", "1000", "--quiet", timeout=300
    )
    assert done.returncode == 0, done.stderr
    return root / "city"


def test_a_200_px_surface_gate_is_computed_once_per_patch_in_a_few_hundred_passes(city, tmp_path):
    """The gate's disc of 200 px used to be visited pixel by pixel (126,000 visits per pixel, twice
    per patch: 15 core seconds for this city's one window, where the default spends 0.4 on the
    whole patch); its decisions are checked against that in tests/graph/test_disc_filter.py."""
    done = run_cli(
        "predict",
        str(city),
        "--out",
        str(tmp_path / "gate"),
        "--quiet",
        "--device",
        "cpu",
        "--surface-gate",
        "200",
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "gate" / "summary.json").read_text())
    assert summary["settings"]["graph"]["surface_gate"] == 200 and summary["counts"]["edges"] > 0
    core = summary["core_seconds_per_patch"]  # thread seconds: what the machine's other work does not inflate
    assert core["vertex_extraction"] + core["afanet"] < 3.0, core
