"""Images labelled with raster masks -> cities with vector ground truth; scoring a set of them."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from affine import Affine

from csboundary.data import city_layout
from csboundary.data.ground_truth import read_ground_truth
from csboundary.errors import InputError
from csboundary.labels.mask_import import MaskRule, import_masks, mask_polylines, surface_outline
from helpers import run_cli


def write_png(path, array):
    """(h, w, 3) RGB -> PNG."""
    cv2.imwrite(str(path), np.ascontiguousarray(array[..., ::-1]))


def pair(folder, name="a", size=64, row=20):
    """A 64x64 RGB picture and an edge mask (cyan on black) with one horizontal line at ``row``."""
    folder.mkdir(parents=True, exist_ok=True)
    image = np.random.default_rng(0).integers(0, 256, (size, size, 3), dtype=np.uint8)
    label = np.zeros((size, size, 3), np.uint8)
    label[row, :] = (0, 255, 255)
    write_png(folder / f"{name}_image.png", image)
    write_png(folder / f"{name}_edge.png", label)
    return image


def test_edge_line_is_traced_at_its_pixel_centres():
    mask = np.zeros((30, 40), bool)
    mask[12, 3:35] = True
    (line,) = mask_polylines(mask, MaskRule())
    assert np.allclose(line[:, 1], 12.5)
    assert sorted([line[0, 0], line[-1, 0]]) == [3.5, 34.5]


def test_surface_outline_skips_the_picture_border():
    surface = np.zeros((30, 40), bool)
    surface[10:20, :] = True  # a road crossing the whole picture
    outline = surface_outline(surface)
    assert set(np.nonzero(outline)[0]) == {10, 19}
    assert not outline[:, 0].any() and not outline[:, -1].any()
    lines = mask_polylines(surface, MaskRule(kind="surface"))
    assert sorted(round(float(np.mean(line[:, 1])), 1) for line in lines) == [10.5, 19.5]


def test_import_resamples_image_and_ground_truth_to_the_target_pixel_size(tmp_path):
    pair(tmp_path / "src", row=20)
    report = import_masks(
        tmp_path / "src", tmp_path / "out", gsd=0.3, target_gsd=0.15, rule=MaskRule(channel=1), progress=False
    )
    city = tmp_path / "out" / "a"
    assert city_layout.is_city_dir(city) and report["cities"][0]["size"] == [128, 128]
    meta = city_layout.read_meta(city)
    assert meta["gsd"] == 0.15 and meta["source_gsd"] == 0.3 and meta["georeferenced"] is False
    (line,) = read_ground_truth(city_layout.ground_truth_path(city)).geometry
    # row 20 of the 0.3 m picture: centre y = 20.5 px * 0.3 m = 6.15 m below the origin
    assert np.allclose(np.asarray(line.coords)[:, 1], -6.15, atol=1e-6)
    assert line.length == pytest.approx(63 * 0.3, abs=0.31)


def test_georeferenced_input_keeps_its_crs_and_origin(tmp_path, write_tif):
    src = tmp_path / "src"
    src.mkdir()
    transform = Affine(0.3, 0, 500000.0, 0, -0.3, 4400000.0)
    write_tif(src / "t_image.tif", np.full((3, 32, 32), 90, np.uint8), transform, "EPSG:32618")
    label = np.zeros((1, 32, 32), np.uint8)
    label[0, :, 8] = 255
    write_tif(src / "t_edge.tif", label, transform, "EPSG:32618")
    import_masks(
        src,
        tmp_path / "out",
        gsd=None,
        image_pattern="{id}_image.tif",
        mask_pattern="{id}_edge.tif",
        target_gsd=0.3,
        progress=False,
    )
    (line,) = read_ground_truth(city_layout.ground_truth_path(tmp_path / "out" / "t")).geometry
    assert np.allclose(np.asarray(line.coords)[:, 0], 500000.0 + 8.5 * 0.3)


@pytest.mark.parametrize(
    "crs, transform, size",
    [
        (
            "EPSG:2263",
            Affine(0.5, 0, 987000.0, 0, -0.5, 200000.0),
            64,
        ),  # 0.5 ft = 0.1524 m: as good as the target already
        ("EPSG:4326", Affine(0.3 / 84305.0, 0, -74.0, 0, -0.3 / 111040.0, 40.7), 128),  # 0.3 m in degrees at 40.7 N
    ],
)
def test_feet_and_degrees_are_resampled_by_their_size_in_metres(tmp_path, write_tif, crs, transform, size):
    src = tmp_path / "src"
    src.mkdir()
    write_tif(src / "t_image.tif", np.full((3, 64, 64), 90, np.uint8), transform, crs)
    label = np.zeros((1, 64, 64), np.uint8)
    label[0, :, 8] = 255
    write_tif(src / "t_edge.tif", label, transform, crs)
    target = "0.152" if size == 64 else "0.15"
    done = run_cli(
        "import-masks",
        str(src),
        "--out",
        str(tmp_path / "out"),
        "--image-pattern",
        "{id}_image.tif",
        "--mask-pattern",
        "{id}_edge.tif",
        "--target-gsd",
        target,
        "--quiet",
    )
    assert done.returncode == 0, done.stderr
    meta = city_layout.read_meta(tmp_path / "out" / "t")
    assert (meta["width"], meta["height"]) == (size, size) and meta["pixel_m"] == float(target)
    (line,) = read_ground_truth(city_layout.ground_truth_path(tmp_path / "out" / "t")).geometry
    assert np.allclose(np.asarray(line.coords)[:, 0], transform.c + 8.5 * transform.a, atol=0.02 * transform.a)


def test_a_second_import_adds_to_the_set(tmp_path):
    pair(tmp_path / "src", "a")
    pair(tmp_path / "src", "b", row=30)
    import_masks(tmp_path / "src", tmp_path / "out", gsd=0.15, rule=MaskRule(channel=1), ids=["a"], progress=False)
    import_masks(
        tmp_path / "src", tmp_path / "out", gsd=0.15, rule=MaskRule(channel=2, invert=True), ids=["b"], progress=False
    )
    listing = json.loads((tmp_path / "out" / "set.json").read_text())
    assert [c["dir"] for c in listing["cities"]] == ["a", "b"]
    assert listing["cities"][1]["mask_rule"]["invert"] is True


def test_bad_inputs_name_the_file(tmp_path):
    pair(tmp_path / "src")
    with pytest.raises(InputError, match="--gsd"):
        import_masks(tmp_path / "src", tmp_path / "out", gsd=None, progress=False)
    with pytest.raises(InputError, match="no image"):
        import_masks(tmp_path / "src", tmp_path / "out", gsd=0.2, image_pattern="{id}.jpg", progress=False)
    (tmp_path / "src" / "a_edge.png").write_bytes(b"not a picture")
    with pytest.raises(InputError, match="a_edge.png"):
        import_masks(tmp_path / "src", tmp_path / "out", gsd=0.2, progress=False)


def test_cli_imports_and_scores_a_set(tmp_path):
    pair(tmp_path / "src", "a", size=96, row=40)
    pair(tmp_path / "src", "b", size=96, row=60)
    done = run_cli(
        "import-masks",
        str(tmp_path / "src"),
        "--out",
        str(tmp_path / "set"),
        "--gsd",
        "0.152",
        "--channel",
        "2",
        "--quiet",
    )
    assert done.returncode == 0, done.stderr
    assert "2 cities" in done.stdout
    scores = tmp_path / "scores.json"
    done = run_cli("evaluate-set", str(tmp_path / "set"), "--json", str(scores), "--device", "cpu", "--quiet")
    assert done.returncode == 0, done.stderr
    assert "warning" not in done.stderr  # RGB crops are the documented case, not a surprise
    result = json.loads(scores.read_text())
    per_city = [result["per_city"][n]["metrics"]["f1@5"] or 0.0 for n in ("a", "b")]
    assert result["mean"]["f1@5"] == pytest.approx(sum(per_city) / 2)
    assert "mean (2)" in done.stdout


def test_evaluate_set_of_an_empty_folder_is_a_one_line_error(tmp_path):
    (tmp_path / "empty").mkdir()
    done = run_cli("evaluate-set", str(tmp_path / "empty"), "--device", "cpu")
    assert done.returncode == 2
    assert done.stderr.strip().startswith("error:") and "Traceback" not in done.stderr


def test_make_city_links_tiles_and_reprojects_the_ground_truth(tiles, tmp_path):
    """A user's tiles + curbs in another CRS -> a city whose ground truth is in the tiles' CRS."""
    import geopandas as gpd
    from shapely.geometry import LineString

    from csboundary.data.user_city import make_city

    line = LineString([(500001.0, 4399990.0), (500050.0, 4399990.0)])
    curbs = gpd.GeoDataFrame(geometry=[line], crs="EPSG:32618").to_crs("EPSG:4326")
    curbs.to_file(tmp_path / "curbs.geojson", driver="GeoJSON")
    meta = make_city([tiles.directory], tmp_path / "curbs.geojson", tmp_path / "city")
    assert meta["boundaries"] == 1 and meta["width"] == 120 and meta["height"] == 80
    linked = sorted((tmp_path / "city" / "tiles").iterdir())
    assert len(linked) == 4 and all(p.is_symlink() for p in linked)
    (back,) = read_ground_truth(city_layout.ground_truth_path(tmp_path / "city")).geometry
    assert np.allclose(np.asarray(back.coords), np.asarray(line.coords), atol=1e-3)


def test_make_city_refuses_ground_truth_without_crs_or_off_the_tiles(tiles, tmp_path):
    import geopandas as gpd
    from shapely.geometry import LineString

    gpd.GeoDataFrame(geometry=[LineString([(500001.0, 4399990.0), (500050.0, 4399990.0)])]).to_file(
        tmp_path / "nocrs.gpkg"
    )
    done = run_cli(
        "make-city",
        str(tiles.directory),
        "--ground-truth",
        str(tmp_path / "nocrs.gpkg"),
        "--out",
        str(tmp_path / "city"),
    )
    assert done.returncode == 2 and "has no CRS" in done.stderr and "Traceback" not in done.stderr
    # plain GeoJSON is WGS84 by definition: UTM numbers read as degrees land nowhere near the tiles
    (tmp_path / "curbs.geojson").write_text(
        '{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}, '
        '"geometry": {"type": "LineString", "coordinates": [[10, 10], [11, 11]]}}]}'
    )
    done = run_cli(
        "make-city",
        str(tiles.directory),
        "--ground-truth",
        str(tmp_path / "curbs.geojson"),
        "--out",
        str(tmp_path / "city"),
    )
    assert done.returncode == 2 and "no boundary lies on the tiles" in done.stderr
    assert not (tmp_path / "city" / "city.json").exists()
