"""Hostile input, one case per class: bad file, band count, data type, CRS, pixel size,
geotransform, weights, output location, signals, huge coordinates. Each case runs the command
line as a user does and asserts the exit code, the single ``error:`` line on stderr and what is
left on disk (nothing under a final name unless the run completed)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from affine import Affine

from csboundary.data.geotiff import write_geotiff
from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.styles import style_config
from csboundary.models.afanet import AfANet, AfANetConfig
from csboundary.models.checkpoint import FORMAT, load_checkpoint, save_checkpoint
from csboundary.models.fpn import FPN, FPNConfig
from helpers import obey_file_permissions, run_cli

UTM = "EPSG:32618"
GSD = 0.3  # the tiny test bundle's pixel size, so 0.3 m test imagery is used as it is


def tiny_bundle(path: Path, **changes) -> Path:
    torch.manual_seed(0)
    fpn_config = FPNConfig(widths=(8, 8, 8, 8), blocks=(1, 1, 1, 1), pyramid=8, stem=8)
    afanet_config = AfANetConfig(global_size=64, roi=16, encoder_widths=(8, 8), dim=32, layers=1)
    fpn = FPN(fpn_config)
    with torch.no_grad():
        fpn.head[-1].bias.fill_(-3.0)
    content = {
        "fpn": fpn.state_dict(),
        "fpn_config": fpn_config.to_dict(),
        "afanet": AfANet(afanet_config).state_dict(),
        "afanet_config": afanet_config.to_dict(),
        "inference": {"edge_threshold": 0.5, "max_degree": 2},
        "pixel_size_m": GSD,
    }
    content.update(changes)
    content = {k: v for k, v in content.items() if v is not None}
    return save_checkpoint(path, "bundle", **content)


def image(path: Path, size: int = 300, bands: int = 4, dtype=np.uint8, transform=None, crs=UTM, fill=None) -> Path:
    rng = np.random.default_rng(0)
    data = (
        rng.integers(0, 200, (bands, size, size)).astype(dtype)
        if fill is None
        else np.full((bands, size, size), fill, dtype)
    )
    return write_geotiff(path, data, transform or Affine(GSD, 0, 500000, 0, -GSD, 4400000), crs)


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile")
    return {"root": root, "bundle": tiny_bundle(root / "bundle.pt"), "tif": image(root / "ok.tif")}


def one_error(result: subprocess.CompletedProcess, *needles: str) -> str:
    """The run failed with exit 2 and exactly one ``error:`` line holding every needle."""
    lines = [line for line in result.stderr.strip().splitlines() if not line.startswith("warning:")]
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def predict(world, *inputs, out=None, extra=()):
    out = out or world["root"] / "out"
    return run_cli(
        "predict",
        *map(str, inputs),
        "--out",
        str(out),
        "--weights",
        str(world["bundle"]),
        "--device",
        "cpu",
        "--quiet",
        *extra,
    )


def final_files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


# -- files and pixels ---------------------------------------------------------------------------------
def test_a_text_file_is_not_a_raster(world, tmp_path):
    bad = tmp_path / "notes.tif"
    bad.write_text("hello")
    one_error(predict(world, bad, out=tmp_path / "out"), str(bad), "not a raster")
    assert not (tmp_path / "out").exists()  # refused before any output folder was made


def test_two_bands_are_refused_naming_the_file(world, tmp_path):
    path = image(tmp_path / "two.tif", bands=2)
    one_error(predict(world, path, out=tmp_path / "out"), str(path), "2 band(s)")
    assert not (tmp_path / "out").exists()


def test_float_imagery_with_nan_is_stretched_and_nan_is_nodata(world, tmp_path):
    data = np.random.default_rng(1).random((4, 300, 300)).astype(np.float32) * 0.3
    data[:, :50] = np.nan
    path = write_geotiff(tmp_path / "float.tif", data, Affine(GSD, 0, 500000, 0, -GSD, 4400000), UTM)
    result = predict(world, path, out=tmp_path / "out")
    assert result.returncode == 0, result.stderr
    assert f"{path}: float32 imagery stretched to 8 bits" in result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["settings"]["stretch"]["high"][0] <= 0.3


def test_uint16_imagery_runs_with_a_stretch(world, tmp_path):
    path = image(tmp_path / "u16.tif", dtype=np.uint16)
    result = predict(world, path, out=tmp_path / "out")
    assert result.returncode == 0 and "uint16 imagery stretched" in result.stderr


# -- georeference ------------------------------------------------------------------------------------
def test_no_crs_needs_the_pixel_size(world, tmp_path):
    path = image(tmp_path / "plain.tif", transform=Affine.identity(), crs=None)
    one_error(predict(world, path, out=tmp_path / "out"), str(path), "no CRS", "--gsd")
    assert not (tmp_path / "out").exists()
    result = predict(world, path, out=tmp_path / "out", extra=("--gsd", "0.3"))
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["area_km2"] == pytest.approx(300 * 300 * 0.09 / 1e6, rel=1e-6)  # pixels of 0.3 m, not of 1 m


def test_pixel_size_far_from_the_models_is_refused(world, tmp_path):
    path = image(tmp_path / "coarse.tif", transform=Affine(4.5, 0, 500000, 0, -4.5, 4400000))
    one_error(predict(world, path, out=tmp_path / "out"), str(path), "pixel size 4.5 m is outside")


def test_resampled_pixel_size_is_warned_and_lengths_stay_metres(world, tmp_path):
    path = image(tmp_path / "fine.tif", size=400, transform=Affine(0.15, 0, 500000, 0, -0.15, 4400000))
    result = predict(world, path, out=tmp_path / "out")
    assert result.returncode == 0, result.stderr
    assert "pixel size 0.15 m resampled to the model's 0.3 m" in result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["mosaic_px"] == [200, 200] and summary["area_km2"] == pytest.approx(0.0036, rel=1e-6)


def test_rotated_georeference_is_refused(world, tmp_path):
    path = image(tmp_path / "rot.tif", transform=Affine(0.2, 0.1, 500000, 0.1, -0.2, 4400000))
    one_error(predict(world, path, out=tmp_path / "out"), str(path), "rotated")


def test_us_feet_are_converted_to_metres(world, tmp_path):
    feet = 0.3 / 0.3048006096  # one pixel is 0.3 m, expressed in US survey feet
    path = image(tmp_path / "feet.tif", transform=Affine(feet, 0, 980000, 0, -feet, 200000), crs="EPSG:2263")
    result = predict(world, path, out=tmp_path / "out")
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["area_km2"] == pytest.approx(300 * 300 * 0.09 / 1e6, rel=1e-3)
    assert "US survey foot" in summary["length_unit"]
    import geopandas as gpd

    edges = gpd.read_file(tmp_path / "out" / "boundaries.gpkg", layer="edges")
    if len(edges):  # lengths in the GeoPackage are metres, not feet
        assert edges["length_m"].sum() == pytest.approx(edges.length.sum() * 1200 / 3937, rel=1e-3)


def test_geographic_crs_is_measured_on_the_ellipsoid(world, tmp_path):
    from pyproj import Geod

    lat = 40.7
    dlon, dlat = 0.3 / 84305.0, 0.3 / 111040.0  # about 0.3 m at 40.7 N
    path = image(tmp_path / "wgs84.tif", transform=Affine(dlon, 0, -74.0, 0, -dlat, lat), crs="EPSG:4326")
    result = predict(world, path, out=tmp_path / "out")
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    area, _ = Geod(ellps="WGS84").polygon_area_perimeter(
        [-74, -74 + 300 * dlon, -74 + 300 * dlon, -74], [lat - 300 * dlat] * 2 + [lat] * 2
    )
    assert summary["area_km2"] == pytest.approx(abs(area) / 1e6, rel=1e-3)
    assert summary["area_km2"] > 0.005 and "geodesic" in summary["length_unit"]
    assert summary["mosaic_px"][0] == pytest.approx(300, abs=3)  # square 0.3 m pixels on the ground


def curbed_image(folder: Path, transform: Affine, crs: str) -> tuple[Path, Path]:
    """A 120 px GeoTIFF and a GeoPackage with one curb on it (both in ``crs``), for make-city."""
    import geopandas as gpd
    from shapely.geometry import LineString

    folder.mkdir(parents=True, exist_ok=True)
    tif = image(folder / "tile.tif", size=120, transform=transform, crs=crs)
    curb = [transform @ (5.5, 10.5), transform @ (100.5, 10.5)]
    gpd.GeoDataFrame(geometry=[LineString(curb)], crs=crs).to_file(folder / "curbs.gpkg")
    return tif, folder / "curbs.gpkg"


@pytest.mark.parametrize(
    "crs, transform, metres, warned",
    [
        ("EPSG:2263", Affine(0.5, 0, 987000, 0, -0.5, 200000), "0.152", False),  # NYC's own 0.5 ft: the model's pixel
        ("EPSG:2263", Affine(0.5 / 0.3048006, 0, 987000, 0, -0.5 / 0.3048006, 200000), "0.5", True),  # 0.5 m in feet
        (
            "EPSG:4326",
            Affine(0.152 / 84305.0, 0, -74.0, 0, -0.152 / 111040.0, 40.7),
            "0.152",
            False,
        ),  # 0.152 m in degrees at 40.7 N
    ],
)
def test_make_city_gives_and_compares_pixel_sizes_in_metres(tmp_path, crs, transform, metres, warned):
    """Feet and degrees are not metres: a city at the model's pixel size is not told to resample."""
    tif, curbs = curbed_image(tmp_path / "in", transform, crs)
    result = run_cli("make-city", str(tif), "--ground-truth", str(curbs), "--out", str(tmp_path / "city"))
    assert result.returncode == 0, result.stderr
    assert f"120x120 px at {metres} m," in result.stdout
    assert ("resample the tiles" in result.stderr) is warned, result.stderr
    if warned:
        assert f"pixel size {metres} m differs from the model's 0.152 m" in result.stderr
    meta = json.loads((tmp_path / "city" / "city.json").read_text())
    assert meta["pixel_m"] == pytest.approx(float(metres), rel=0.01) and meta["gsd"] == pytest.approx(transform.a)


def test_a_bundle_trained_on_a_feet_city_records_its_pixel_size_in_metres(tmp_path):
    """The bundle's pixel size is what every input is resampled to: NYC's 0.5 ft is 0.1524 m, not 0.5 m."""
    tif, curbs = curbed_image(tmp_path / "in", Affine(0.5, 0, 987000, 0, -0.5, 200000), "EPSG:2263")
    assert run_cli("make-city", str(tif), "--ground-truth", str(curbs), "--out", str(tmp_path / "city")).returncode == 0
    bundle = load_checkpoint(tiny_bundle(tmp_path / "tiny.pt"), ("bundle",))
    train_config = {"model": "fpn", "train_city": None, "extra_train_cities": [str(tmp_path / "city")]}
    save_checkpoint(
        tmp_path / "fpn.pt", "fpn", fpn=bundle["fpn"], fpn_config=bundle["fpn_config"], train_config=train_config
    )
    save_checkpoint(tmp_path / "afanet.pt", "afanet", afanet=bundle["afanet"], afanet_config=bundle["afanet_config"])
    result = run_cli(
        "bundle-weights",
        "--fpn",
        str(tmp_path / "fpn.pt"),
        "--afanet",
        str(tmp_path / "afanet.pt"),
        "--out",
        str(tmp_path / "b.pt"),
    )
    assert result.returncode == 0, result.stderr
    assert load_checkpoint(tmp_path / "b.pt", ("bundle",))["pixel_size_m"] == pytest.approx(0.1524, abs=1e-4)


# -- weights -----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "case, needle",
    [
        ("junk", "not a readable weights file"),
        ("no_fpn_config", "no 'fpn_config' entry"),
        ("wrong_shapes", "tensors do not fit its config"),
        ("edge_threshold_7", "edge_threshold = 7"),
        ("max_degree_minus_1", "max_degree = -1"),
        ("code", "refused"),
        ("folder", "is a folder"),
    ],
)
def test_damaged_or_hostile_weights_are_one_line(world, tmp_path, case, needle):
    path = tmp_path / "w.pt"
    marker = tmp_path / "PWNED"
    if case == "junk":
        path.write_text("no weights here")
    elif case == "no_fpn_config":
        tiny_bundle(path, fpn_config=None)
    elif case == "wrong_shapes":
        other = FPN(FPNConfig(widths=(16, 16, 16, 16), blocks=(1, 1, 1, 1), pyramid=8, stem=8)).state_dict()
        tiny_bundle(path, fpn=other)
    elif case == "edge_threshold_7":
        tiny_bundle(path, inference={"edge_threshold": 7})
    elif case == "max_degree_minus_1":
        tiny_bundle(path, inference={"max_degree": -1})
    elif case == "code":

        class Evil:
            def __reduce__(self):
                return (os.system, (f"touch {marker}",))

        torch.save({"format": FORMAT, "kind": "bundle", "x": Evil()}, path)
    elif case == "folder":
        path.mkdir()
    result = run_cli(
        "predict",
        str(world["tif"]),
        "--out",
        str(tmp_path / "out"),
        "--weights",
        str(path),
        "--device",
        "cpu",
        "--quiet",
    )
    one_error(result, str(path), needle)
    assert not marker.exists()  # nothing in a weights file ever runs
    assert not (tmp_path / "out").exists()


def confidence_table(**changes) -> dict:
    """A well-formed edge confidence over the score alone: one split at 0.5, leaves -2 and +2, an
    increasing isotonic map; ``changes`` damage it."""
    table = {
        "version": 1,
        "features": ["score"],
        "learning_rate": 0.1,
        "tree_starts": [0, 3],
        "feature": [0, -1, -1],
        "threshold": [0.5, 0.0, 0.0],
        "left": [1, -1, -1],
        "right": [2, -1, -1],
        "value": [0.0, -2.0, 2.0],
        "iso_x": [-0.2, 0.2],
        "iso_y": [0.1, 0.9],
        "provenance": {},
    }
    return {**table, **changes}


def test_a_sound_confidence_table_is_accepted(world, tmp_path):
    bundle = tiny_bundle(tmp_path / "w.pt", confidence=confidence_table())
    result = run_cli(
        "predict",
        str(world["tif"]),
        "--out",
        str(tmp_path / "out"),
        "--weights",
        str(bundle),
        "--device",
        "cpu",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    assert "overflow" not in result.stderr


@pytest.mark.parametrize(
    "changes, needle",
    [
        ({"value": [0.0, -1e308, 1e308]}, "leaf value beyond"),
        ({"iso_y": [0.9, 0.1]}, "isotonic map decreases"),
        ({"iso_y": [0.1, 1.5]}, "isotonic map is not"),
        ({"learning_rate": 1e300}, "learning rate"),
        ({"value": [0.0, float("nan"), 2.0]}, "not a finite number"),
    ],
)
def test_a_damaged_confidence_table_is_one_line(world, tmp_path, changes, needle):
    bundle = tiny_bundle(tmp_path / "w.pt", confidence=confidence_table(**changes))
    result = run_cli(
        "predict",
        str(world["tif"]),
        "--out",
        str(tmp_path / "out"),
        "--weights",
        str(bundle),
        "--device",
        "cpu",
        "--quiet",
    )
    one_error(result, str(bundle), needle)
    assert not (tmp_path / "out").exists()


def test_finetune_checks_the_base_bundle_before_training(world, tmp_path):
    bundle = tiny_bundle(tmp_path / "w.pt", confidence=confidence_table(value=[0.0, float("nan"), 2.0]))
    city = tmp_path / "city"
    synthesize_city(city, seed=3, split="valid", config=style_config("classic", tile_size=300), progress=False)
    result = run_cli(
        "finetune", str(city), "--weights", str(bundle), "--out", str(tmp_path / "tuned.pt"), "--device", "cpu"
    )
    one_error(result, str(bundle), "not a finite number")
    assert final_files(tmp_path) == ["city", "w.pt"]  # no tuned bundle, no work folder


@pytest.mark.parametrize("device, needle", [("tpu", "must be auto, cpu, cuda"), ("cuda:7", "CUDA")])
def test_unknown_or_missing_device_is_one_line(world, tmp_path, device, needle):
    if device.startswith("cuda") and torch.cuda.device_count() > 7:
        pytest.skip("this machine has 8 GPUs")
    one_error(predict(world, world["tif"], out=tmp_path / "out", extra=("--device", device)), "--device", needle)


# -- output location ---------------------------------------------------------------------------------
def test_out_naming_an_existing_file_is_refused_before_work(world, tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("keep me")
    one_error(predict(world, world["tif"], out=taken), str(taken), "not a folder")
    assert taken.read_text() == "keep me"


def test_out_below_a_file_is_refused(world, tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    one_error(predict(world, world["tif"], out=blocker / "out"), "is a file")


def test_out_inside_the_input_folder_is_refused(world, tmp_path):
    folder = tmp_path / "tiles"
    image(folder / "a.tif")
    one_error(predict(world, folder, out=folder / "pred"), "inside the input folder")
    assert final_files(folder) == ["a.tif"]


def test_json_and_picture_outputs_are_checked_first(world, tmp_path):
    city = tmp_path / "city"
    assert run_cli("synth", str(city), "--tile-size", "300", "--gsd", "0.3", "--quiet").returncode == 0
    one_error(run_cli("show", str(city), "--out", str(tmp_path / "picture")), "needs one of the extensions .png")
    one_error(run_cli("show", str(city), "--out", str(tmp_path)), "is a folder")
    one_error(
        run_cli("evaluate-model", str(city), "--weights", str(world["bundle"]), "--json", str(tmp_path), "--quiet"),
        "is a folder",
    )


def test_a_city_folder_without_city_json_is_refused(world, tmp_path):
    city = tmp_path / "city"
    image(city / "tiles" / "t.tif")
    one_error(predict(world, city, out=tmp_path / "out"), "no city.json")


# -- signals and leftovers ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def slow_city(tmp_path_factory):
    city = tmp_path_factory.mktemp("slow") / "city"
    done = run_cli("synth", str(city), "--tiles", "2x2", "--tile-size", "1200", "--gsd", "0.3", "--quiet")
    assert done.returncode == 0, done.stderr
    return city


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_leaves_no_final_file_and_no_temporary(world, slow_city, tmp_path, signum, code):
    out = tmp_path / "out"
    job = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "csboundary",
            "predict",
            str(slow_city),
            "--out",
            str(out),
            "--weights",
            str(world["bundle"]),
            "--device",
            "cpu",
            "--quiet",
            "--write-maps",
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.time() + 120
    while not any(p.name.startswith(".run.partial-") for p in (out.iterdir() if out.exists() else [])):
        assert job.poll() is None and time.time() < deadline, "the run ended before it could be interrupted"
        time.sleep(0.05)
    time.sleep(0.5)
    job.send_signal(signum)
    _, err = job.communicate(timeout=60)
    assert job.returncode == code, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("interrupted")
    assert final_files(out) == [".csboundary-run"]  # no final file, no temporary, no scratch; the finished work, kept
    store = out / ".csboundary-run"
    assert not [p for p in store.rglob(".*") if "partial" in p.name]  # every stored file is complete


def test_leftovers_of_a_killed_run_are_cleared_by_the_next(world, tmp_path):
    out = tmp_path / "out"
    dead = 2**22 + 12345  # above Linux's default pid_max of 4194304: no such process
    (out / f".run.partial-{dead}").mkdir(parents=True)
    (out / f".run.partial-{dead}" / "maps.tif").write_bytes(b"x" * 1000)
    (out / f".maps.scratch-{dead}.tif").write_bytes(b"x" * 1000)
    (out / f".maps.partial-{dead}.tif.ovr.tmp").write_bytes(b"x")
    result = predict(world, world["tif"], out=out)
    assert result.returncode == 0, result.stderr
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    assert "summary.json" in final_files(out)


def test_geojson_layer_is_named_boundaries_not_the_temporary(world, tmp_path):
    assert predict(world, world["tif"], out=tmp_path / "out").returncode == 0
    assert json.loads((tmp_path / "out" / "boundaries.geojson").read_text())["name"] == "boundaries"


# -- coordinate spaces of evaluate ----------------------------------------------------------------------
def labelled_picture(folder: Path, size: int = 96) -> Path:
    """A plain RGB picture (no CRS) and its edge mask, as import-masks and predict-patch take them."""
    import cv2

    folder.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(folder / "a_image.png"), np.random.default_rng(0).integers(0, 256, (size, size, 3), dtype=np.uint8))
    label = np.zeros((size, size, 3), np.uint8)
    label[size // 2, :] = 255
    cv2.imwrite(str(folder / "a_edge.png"), label)
    return folder / "a_image.png"


def test_a_prediction_of_a_picture_without_crs_is_not_scored_against_an_imported_city(world, tmp_path):
    """import-masks places the picture in metres of EPSG:32618; predict-patch on the same picture
    gives its pixels, without a CRS. Scored against each other they got near 0 without a word."""
    picture = labelled_picture(tmp_path / "src")
    done = run_cli("import-masks", str(tmp_path / "src"), "--out", str(tmp_path / "set"), "--gsd", str(GSD), "--quiet")
    assert done.returncode == 0, done.stderr
    done = run_cli(
        "predict-patch",
        str(picture),
        "--gsd",
        str(GSD),
        "--out",
        str(tmp_path / "pred"),
        "--weights",
        str(world["bundle"]),
        "--device",
        "cpu",
    )
    assert done.returncode == 0, done.stderr
    pred = tmp_path / "pred" / "graph.json"
    for gt in (tmp_path / "set" / "a", tmp_path / "set" / "a" / "ground_truth.gpkg"):
        one_error(
            run_cli("evaluate", str(pred), str(gt)), f"{pred}: has no CRS but {gt} is in EPSG:32618", "evaluate-set"
        )
    one_error(run_cli("evaluate", str(tmp_path / "set" / "a" / "ground_truth.gpkg"), str(pred)), f"{pred}: has no CRS")


def test_world_coordinates_with_and_without_a_crs_are_not_mixed_but_two_crss_are_reprojected(world, tmp_path):
    import geopandas as gpd
    from shapely.geometry import LineString

    curbs = [
        LineString([(500003.0, 4399970.0), (500080.0, 4399970.0)]),
        LineString([(500003.0, 4399940.0), (500080.0, 4399940.0)]),
    ]
    gpd.GeoDataFrame(geometry=curbs, crs=UTM).to_file(tmp_path / "pred.gpkg")
    gpd.GeoDataFrame(geometry=curbs).to_file(tmp_path / "nocrs.gpkg")  # the same numbers, CRS left out
    one_error(
        run_cli("evaluate", str(tmp_path / "pred.gpkg"), str(tmp_path / "nocrs.gpkg"), "--gsd", "0.3"),
        "nocrs.gpkg: has no CRS but",
        "is in EPSG:32618",
        "ogr2ogr -a_srs EPSG:32618",
    )
    plain = image(tmp_path / "plain.tif", transform=Affine.identity(), crs=None)
    one_error(
        run_cli("evaluate", str(tmp_path / "pred.gpkg"), str(tmp_path / "pred.gpkg"), "--raster", str(plain)),
        f"{plain}: has no CRS",
        "give a georeferenced raster",
    )
    gpd.GeoDataFrame(geometry=curbs, crs=UTM).to_crs("EPSG:4326").to_file(tmp_path / "gt.geojson", driver="GeoJSON")
    done = run_cli(
        "evaluate",
        str(tmp_path / "pred.gpkg"),
        str(tmp_path / "gt.geojson"),
        "--raster",
        str(world["tif"]),
        "--json",
        str(tmp_path / "s.json"),
    )
    assert done.returncode == 0, done.stderr  # two CRSs: reprojected, the same lines score 1
    assert json.loads((tmp_path / "s.json").read_text())["metrics"]["f1@2"] == pytest.approx(1.0)


# -- huge coordinates --------------------------------------------------------------------------------
def test_a_far_away_label_point_is_refused_in_one_line_without_memory(tmp_path):
    gt = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "LineString", "coordinates": [[10, 10], [-500, 2e9]]},
            }
        ],
    }
    pred = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "LineString", "coordinates": [[10, 10], [50, 50]]},
            }
        ],
    }
    (tmp_path / "gt.geojson").write_text(json.dumps(gt))
    (tmp_path / "pred.geojson").write_text(json.dumps(pred))
    result = run_cli("evaluate", str(tmp_path / "pred.geojson"), str(tmp_path / "gt.geojson"), "--pixels", timeout=120)
    one_error(result, "far outside the imagery")


def test_an_infinite_vertex_is_refused(tmp_path):
    from csboundary.graph.boundary_graph import FORMAT as GRAPH
    from csboundary.graph.boundary_graph import VERSION

    graph = {
        "format": GRAPH,
        "version": VERSION,
        "vertices": [{"px": [0, 0]}, {"px": [float("inf"), 5]}],
        "edges": [{"u": 0, "v": 1}],
    }
    (tmp_path / "g.json").write_text(json.dumps(graph))
    one_error(run_cli("evaluate", str(tmp_path / "g.json"), str(tmp_path / "g.json"), "--pixels"), "g.json", "finite")


def test_show_clips_a_huge_window_to_the_imagery(world, tmp_path):
    result = run_cli(
        "show", str(world["tif"]), "--out", str(tmp_path / "a.png"), "--window", "0,0,10000000,10000000", timeout=120
    )
    assert result.returncode == 0, result.stderr
    one_error(
        run_cli("show", str(world["tif"]), "--out", str(tmp_path / "b.png"), "--window", "5000,5000,10,10"),
        "outside the imagery",
    )
    assert not (tmp_path / "b.png").exists()


def test_nan_and_inf_options_are_usage_errors(world, tmp_path):
    one_error(run_cli("synth", str(tmp_path / "c"), "--gsd", "nan"), "--gsd")
    one_error(predict(world, world["tif"], out=tmp_path / "o", extra=("--gsd", "inf")), "--gsd")


@pytest.mark.parametrize("command", ["predict", "predict-patch"])
def test_a_pixel_size_of_zero_is_a_usage_error(world, tmp_path, command):
    done = run_cli(
        command, str(world["tif"]), "--out", str(tmp_path / "o"), "--weights", str(world["bundle"]), "--gsd", "0"
    )
    one_error(done, "--gsd", "positive pixel size")
    assert not (tmp_path / "o").exists()


def test_a_training_config_must_name_its_training_data(tmp_path):
    (tmp_path / "empty.json").write_text("{}")
    done = run_cli("train", "fpn", "--config", str(tmp_path / "empty.json"), "--out", str(tmp_path / "run"))
    one_error(done, "empty.json", "names no training data", "worlds")
    assert not (tmp_path / "run" / "train.log").exists()


@pytest.mark.parametrize(
    "command",
    [
        ["predict", "{missing}", "--out", "{out}"],
        ["predict-patch", "{missing}", "--out", "{out}"],
        ["evaluate-model", "{missing}"],
    ],
)
def test_a_missing_input_is_reported_before_pytorch_loads(tmp_path, command):
    """The one-line error comes from opening the imagery, which needs no network: PyTorch is never imported."""
    args = [a.format(missing=tmp_path / "missing.tif", out=tmp_path / "out") for a in command]
    probe = (
        "import sys\nfrom csboundary.cli.main import main\nsys.argv = ['csboundary', *sys.argv[1:]]\n"
        "try:\n    main()\nfinally:\n    print('torch imported:', 'torch' in sys.modules)\n"
    )
    result = subprocess.run([sys.executable, "-c", probe, *args], capture_output=True, text=True, timeout=120)
    one_error(result, "missing.tif")
    assert "torch imported: False" in result.stdout
    assert not (tmp_path / "out").exists()


def test_predict_names_what_it_wrote_and_counts_in_english(world, tmp_path):
    result = predict(world, world["tif"], out=tmp_path / "out")
    assert result.returncode == 0, result.stderr
    assert "1 patch (1x1)" in result.stderr and "1 patches" not in result.stdout + result.stderr
    wrote = [line for line in result.stdout.splitlines() if line.startswith(f"wrote {tmp_path / 'out'}: ")]
    assert len(wrote) == 1
    named = wrote[0].split(": ", 1)[1].split(", ")
    assert named == final_files(tmp_path / "out") and {"graph.json", "boundaries.gpkg", "summary.json"} <= set(named)


# -- one run per output folder -----------------------------------------------------------------------
def _start_predict(world, inputs, out: Path) -> subprocess.Popen:
    """``predict`` started in the background, returned once it is working in ``out`` (its staging folder made)."""
    job = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "csboundary",
            "predict",
            str(inputs),
            "--out",
            str(out),
            "--weights",
            str(world["bundle"]),
            "--device",
            "cpu",
            "--quiet",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.time() + 120
    while not any(p.name.startswith(".run.partial-") for p in (out.iterdir() if out.exists() else [])):
        assert job.poll() is None and time.time() < deadline, "the run ended before the test could meet it"
        time.sleep(0.02)
    return job


def test_a_second_run_into_a_folder_in_use_is_refused_and_the_first_completes(world, slow_city, tmp_path):
    out = tmp_path / "out"
    first = _start_predict(world, slow_city, out)
    os.kill(first.pid, signal.SIGSTOP)  # held mid-run, so the second meets it however slow this machine is
    try:
        second = predict(world, slow_city, out=out)
    finally:
        os.kill(first.pid, signal.SIGCONT)
    one_error(second, str(out), "in use by another csboundary run", f"pid {first.pid} on ", "started ")
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["work"]["patches_predicted"] == 9 and summary["work"]["windows_connected"] == 9  # all its own work
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no lock file, no store, no temporary


def test_the_lock_of_a_killed_run_blocks_nothing(world, slow_city, tmp_path):
    out = tmp_path / "out"
    killed = _start_predict(world, slow_city, out)
    killed.kill()  # SIGKILL: nothing of it runs again, its lock file stays
    killed.wait()
    assert f"pid {killed.pid} " in (out / ".csboundary.lock").read_text()
    again = predict(world, slow_city, out=out)
    assert again.returncode == 0, again.stderr
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


# -- a full disk ---------------------------------------------------------------------------------------
def predict_on_a_filling_disk(world, inputs, out: Path, room: int) -> subprocess.CompletedProcess:
    """``predict`` in a process whose disk is full once ``room`` arrays are stored (numpy.save and
    numpy.savez, the run store's writers, then fail with ENOSPC, as they do on a full disk)."""
    probe = (
        "import errno, sys, numpy as np\nfrom csboundary.cli import main as m\n"
        "room = [int(sys.argv.pop(1))]\n"
        "def filling(write):\n    def full(*a, **k):\n        room[0] -= 1\n        if room[0] < 0:\n"
        "            raise OSError(errno.ENOSPC, 'No space left on device')\n        return write(*a, **k)\n    return full\n"
        "np.save, np.savez = filling(np.save), filling(np.savez)\nsys.argv = ['csboundary', *sys.argv[1:]]\nm.main()\n"
    )
    args = ["predict", str(inputs), "--out", str(out), "--weights", str(world["bundle"]), "--device", "cpu", "--quiet"]
    return subprocess.run([sys.executable, "-c", probe, str(room), *args], capture_output=True, text=True, timeout=600)


def error_lines(result: subprocess.CompletedProcess) -> list[str]:
    assert "Traceback" not in result.stderr, result.stderr
    return [line for line in result.stderr.splitlines() if line.startswith("error")]


def test_a_full_disk_before_any_work_leaves_nothing(world, tmp_path):
    out = tmp_path / "out"
    done = predict_on_a_filling_disk(world, world["tif"], out, room=0)
    assert done.returncode == 1, done.stderr
    assert error_lines(done) == [f"error: {out}: no space left on device; nothing of the run was kept"], done.stderr
    assert not out.exists()  # the folder the run made, gone with its empty work store


def test_a_full_disk_keeps_the_finished_work_for_the_same_command(world, slow_city, tmp_path):
    out = tmp_path / "out"
    done = predict_on_a_filling_disk(world, slow_city, out, room=12)
    [line] = error_lines(done)
    assert done.returncode == 1 and line.startswith(f"error: {out}: no space left on device; the finished work (")
    assert f"is kept in {out / '.csboundary-run'}: free some space and run the same command to continue" in line
    assert final_files(out) == [".csboundary-run"]
    again = predict(world, slow_city, out=out)
    assert again.returncode == 0, again.stderr
    work = json.loads((out / "summary.json").read_text())["work"]
    assert work["patches_reused"] > 0 and work["patches_predicted"] + work["patches_reused"] == 9


# -- review edits and fine-tuning ---------------------------------------------------------------------
MARGIN_RING = [
    [500000 + GSD * col, 4400000 - GSD * row] for col, row in [(-90, 10), (-10, 10), (-10, 80), (-90, 80), (-90, 10)]
]


def test_a_complete_area_wholly_in_the_margin_is_refused(world, tmp_path):
    pred = tmp_path / "pred"
    assert predict(world, world["tif"], out=pred).returncode == 0
    before = (pred / "graph.json").read_bytes()
    edits = tmp_path / "edits.geojson"
    edits.write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"action": "complete"},
                        "geometry": {"type": "Polygon", "coordinates": [MARGIN_RING]},
                    }
                ],
            }
        )
    )
    one_error(
        run_cli("apply-review", str(pred), str(edits)),
        str(edits),
        "edit 0 (complete)",
        "covers no pixel of the imagery",
    )
    assert (pred / "graph.json").read_bytes() == before and not (pred / "review.json").exists()


def test_finetune_refuses_a_margin_area_before_making_anything(world, tmp_path):
    """A review log from before apply-review checked its areas: refused in one line, no work folder made."""
    from csboundary.graph import BoundaryGraph
    from csboundary.pipeline.outputs.prediction_files import write_graph_outputs

    pred = tmp_path / "pred"
    assert predict(world, world["tif"], out=pred).returncode == 0
    predicted = BoundaryGraph.read_json(pred / "graph.json")
    reviewed = BoundaryGraph(
        np.array([[50.0, 20.0], [50.0, 280.0]]),
        [[0, 1]],
        edge_scores=np.array([0.9]),
        transform=predicted.transform,
        crs=predicted.crs,
    )
    reviewed.write_json(pred / "graph.json")
    write_graph_outputs(reviewed, pred)
    (pred / "review.json").write_text(
        json.dumps({"reviews": [{"time": "2025-01-01T00:00:00", "complete_areas": [MARGIN_RING]}]})
    )
    work = tmp_path / "work"
    done = run_cli(
        "finetune",
        str(pred),
        "--out",
        str(tmp_path / "tuned.pt"),
        "--work",
        str(work),
        "--fpn-steps",
        "1",
        "--afanet-steps",
        "1",
        "--synthetic-cities",
        "1",
        "--device",
        "cpu",
        "--quiet",
    )
    one_error(done, str(pred / "review.json"), "no area marked complete in it covers any of the imagery")
    assert not work.exists() and not (tmp_path / "tuned.pt").exists()


def test_apply_review_names_the_folder_it_cannot_write(world, tmp_path):
    pred = tmp_path / "pred"
    assert predict(world, world["tif"], out=pred).returncode == 0
    edits = tmp_path / "edits.geojson"
    edits.write_text(json.dumps({"type": "FeatureCollection", "features": []}))
    pred.chmod(0o555)
    try:
        done = run_cli(
            "apply-review", str(pred), str(edits), preexec_fn=obey_file_permissions if os.geteuid() == 0 else None
        )
    except subprocess.SubprocessError:
        pytest.skip("running as root without the capability to give up CAP_DAC_OVERRIDE")
    finally:
        pred.chmod(0o755)
    one_error(done, f"error: {pred}: cannot write there")
    assert final_files(pred) == [
        "boundaries.geojson",
        "boundaries.gpkg",
        "detail.png",
        "graph.json",
        "overview.png",
        "summary.json",
    ]
