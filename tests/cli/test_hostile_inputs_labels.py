"""Hostile inputs of the commands that make labels (issue 65): a pixel size given in one unit and
read in another, a --gsd that contradicts an image's georeference, and a reviewed area where the
reviewer found no curb at all. Each case runs the command line as a user does and asserts the
right result, or the one ``error:`` line and that nothing was left under a final name."""

from __future__ import annotations

import json
from pathlib import Path

import geopandas as gpd
import numpy as np
import pytest
import rasterio
from affine import Affine
from shapely.geometry import LineString, box

from csboundary.data import city_layout
from csboundary.data.geotiff import write_geotiff
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.units import ground_units, pixel_size_m
from csboundary.data.windows import PixelWindow, pixel_to_world
from csboundary.errors import InputError
from helpers import run_cli

UTM = "EPSG:32618"


def one_error(result, *needles: str) -> str:
    """The run failed with exit 2 and exactly one ``error:`` line holding every needle."""
    lines = [line for line in result.stderr.strip().splitlines() if not line.startswith("warning:")]
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


# -- synth --gsd: metres on the ground, whatever the CRS counts in ------------------------------------
def _synth(out: Path, *extra: str):
    return run_cli(
        "synth", str(out), "--tile-size", "96", "--tiles", "1x2", "--gsd", "0.5", "--split", "valid", "--quiet", *extra
    )


def _tiles(city: Path) -> list[tuple[np.ndarray, Affine, object]]:
    out = []
    for path in sorted(city_layout.tiles_dir(city).glob("*.tif")):
        with rasterio.open(path) as src:
            out.append((src.read(), src.transform, src.crs))
    return out


def _pixel_lines(city: Path, transform: Affine) -> list[np.ndarray]:
    """The city's ground truth in the pixel frame of ``transform``."""
    return [
        np.array([(~transform) @ xy for xy in line.coords])
        for line in read_ground_truth(city_layout.ground_truth_path(city)).geometry
    ]


@pytest.fixture(scope="module")
def utm_city(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth") / "utm"
    done = _synth(out)
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.parametrize("crs", ["EPSG:2263", "EPSG:4326"])  # US survey feet, degrees
def test_synth_gsd_is_metres_per_pixel_in_any_crs(utm_city, tmp_path, crs):
    done = _synth(tmp_path / "city", "--crs", crs)
    assert done.returncode == 0, done.stderr
    tiles, metric = _tiles(tmp_path / "city"), _tiles(utm_city)
    for (pixels, transform, tile_crs), (same_pixels, _, _) in zip(tiles, metric, strict=True):
        assert tile_crs.to_string() == crs
        east, north = pixel_size_m(ground_units(tile_crs, (transform.c, transform.f)), transform)
        assert east == pytest.approx(0.5, rel=0.01) and north == pytest.approx(0.5, rel=0.01)
        assert np.array_equal(pixels, same_pixels)  # the same city on the same ground, only counted in other units
    lines, same_lines = _pixel_lines(tmp_path / "city", tiles[0][1]), _pixel_lines(utm_city, metric[0][1])
    assert len(lines) == len(same_lines) > 0
    for line, same in zip(lines, same_lines, strict=True):  # the ground truth lies on the same pixels
        assert np.abs(line - same).max() < 0.05
    meta = city_layout.read_meta(tmp_path / "city")
    assert meta["pixel_m"] == 0.5 and city_layout.pixel_metres(meta) == 0.5
    assert meta["counts"]["boundary_km"] == city_layout.read_meta(utm_city)["counts"]["boundary_km"]


def test_synth_from_python_in_feet_keeps_gsd_in_metres(tmp_path):
    """A SynthConfig whose CRS counts US feet: its tiles were 0.5 ft (0.15 m) for gsd 0.5 before."""
    from csboundary.data.synth.city import synthesize_city
    from csboundary.data.synth.config import SynthConfig

    config = SynthConfig(tile_size=96, gsd=0.5, crs="EPSG:2263", origin_x=979000.0, origin_y=198000.0)
    meta = synthesize_city(tmp_path / "city", 0, "valid", config=config, progress=False)
    [(_, transform, crs)] = _tiles(tmp_path / "city")
    assert pixel_size_m(ground_units(crs, (transform.c, transform.f)), transform) == pytest.approx((0.5, 0.5), rel=0.01)
    assert (
        meta["units"] == "US survey foot"
        and meta["gsd"] == pytest.approx(0.5 / 0.3048006)
        and city_layout.pixel_metres(meta) == 0.5
    )


def test_synth_help_says_metres_and_an_unknown_crs_is_one_line(tmp_path):
    helped = run_cli("synth", "--help")
    assert "metres per pixel on the ground" in " ".join(helped.stdout.replace("│", " ").split())
    one_error(_synth(tmp_path / "city", "--crs", "EPSG:999999"), "--crs", "EPSG:999999")
    assert not (tmp_path / "city").exists()


# -- import-masks --gsd on a georeferenced image ------------------------------------------------------
def _pair(folder: Path, name: str, transform: Affine, crs: str = UTM) -> None:
    """A 64x64 GeoTIFF image and its edge mask (one vertical line at column 20), georeferenced."""
    folder.mkdir(parents=True, exist_ok=True)
    write_geotiff(
        folder / f"{name}_image.tif",
        np.random.default_rng(0).integers(0, 200, (3, 64, 64)).astype(np.uint8),
        transform,
        crs,
    )
    mask = np.zeros((1, 64, 64), np.uint8)
    mask[0, 4:60, 20] = 255
    write_geotiff(folder / f"{name}_edge.tif", mask, transform, crs)


def _import(src: Path, out: Path, *extra: str):
    return run_cli(
        "import-masks",
        str(src),
        "--out",
        str(out),
        "--image-pattern",
        "{id}_image.tif",
        "--mask-pattern",
        "{id}_edge.tif",
        "--quiet",
        *extra,
    )


def test_import_masks_refuses_a_gsd_that_contradicts_the_georeference_before_writing_anything(tmp_path):
    src = tmp_path / "src"
    _pair(src, "a", Affine(0.3, 0, 500000, 0, -0.3, 4400000))
    _pair(src, "b", Affine(0.6, 0, 500000, 0, -0.6, 4400000))  # the second image is coarser: --gsd 0.3 is wrong for it
    one_error(_import(src, tmp_path / "out", "--gsd", "0.3"), str(src / "b_image.tif"), "--gsd 0.3 m", "0.6 m", UTM)
    assert not (tmp_path / "out" / "a").exists() and not (tmp_path / "out" / "set.json").exists()


def test_import_masks_takes_a_gsd_that_agrees_and_uses_the_crs_size(tmp_path):
    src = tmp_path / "src"
    _pair(src, "a", Affine(0.3, 0, 500000, 0, -0.3, 4400000))
    done = _import(src, tmp_path / "out", "--gsd", "0.303", "--target-gsd", "0.3")  # 1 % off: the same size, rounded
    assert done.returncode == 0 and not done.stderr.strip(), done.stderr
    meta = city_layout.read_meta(tmp_path / "out" / "a")
    assert meta["source_gsd"] == pytest.approx(0.3) and (meta["width"], meta["height"]) == (64, 64)
    assert json.loads((tmp_path / "out" / "set.json").read_text())["cities"][0]["source_gsd"] == pytest.approx(0.3)


def test_import_masks_reads_a_gsd_in_metres_not_in_the_crs_units(tmp_path):
    """0.5 ft pixels (EPSG:2263): --gsd 0.5, the number in the CRS's units, is 0.1524 m and refused;
    --gsd 0.152, metres, is the same size and taken."""
    src = tmp_path / "src"
    _pair(src, "a", Affine(0.5, 0, 987000.0, 0, -0.5, 200000.0), "EPSG:2263")
    one_error(
        _import(src, tmp_path / "out", "--gsd", "0.5"), str(src / "a_image.tif"), "--gsd 0.5 m", "0.1524 m", "EPSG:2263"
    )
    assert not (tmp_path / "out" / "a").exists()
    done = _import(src, tmp_path / "out", "--gsd", "0.152")
    assert done.returncode == 0, done.stderr
    assert city_layout.read_meta(tmp_path / "out" / "a")["source_gsd"] == pytest.approx(0.1524, rel=1e-3)


# -- a reviewed area without a single boundary is a label -----------------------------------------------
SIZE = 200


@pytest.fixture(scope="module")
def reviewed_empty(tmp_path_factory) -> Path:
    """A prediction with one boundary (column 60) that the reviewer deleted, marking the left 150
    columns complete through apply-review: there is no curb there."""
    from csboundary.data.raster import Mosaic
    from csboundary.data.synth.city import synthesize_city
    from csboundary.data.synth.styles import style_config
    from csboundary.graph import BoundaryGraph
    from csboundary.pipeline.outputs.prediction_files import write_graph_outputs

    root = tmp_path_factory.mktemp("reviewed")
    city = root / "city"
    synthesize_city(city, seed=3, split="valid", config=style_config("classic", tile_size=SIZE), progress=False)
    tiles = sorted(city_layout.tiles_dir(city).glob("*.tif"))
    with Mosaic.open(tiles) as mosaic:
        transform, crs = mosaic.transform, mosaic.crs.to_string()
    graph = BoundaryGraph(
        np.array([[60.0, 20.0], [60.0, 180.0]]), [[0, 1]], edge_scores=np.array([0.9]), transform=transform, crs=crs
    )
    pred = root / "pred"
    pred.mkdir()
    graph.write_json(pred / "graph.json")
    write_graph_outputs(graph, pred)
    (pred / "summary.json").write_text(
        json.dumps({"inputs": [str(t.resolve()) for t in tiles], "mosaic_px": [SIZE, SIZE]})
    )
    world = lambda col, row: [float(v) for v in pixel_to_world(transform, col, row)]  # noqa: E731
    xs, ys = pixel_to_world(transform, np.array([0.0, 150.0]), np.array([0.0, float(SIZE)]))
    ring = [list(map(float, p)) for p in box(min(xs), min(ys), max(xs), max(ys)).exterior.coords]
    (root / "edits.geojson").write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"action": "delete", "edge": 0},
                        "geometry": {"type": "LineString", "coordinates": [world(60.0, 20.0), world(60.0, 180.0)]},
                    },
                    {
                        "type": "Feature",
                        "properties": {"action": "complete"},
                        "geometry": {"type": "Polygon", "coordinates": [ring]},
                    },
                ],
            }
        )
    )
    done = run_cli("apply-review", str(pred), str(root / "edits.geojson"))
    assert done.returncode == 0 and "1 -> 0 edges" in done.stdout, done.stderr
    return pred


def test_a_reviewed_area_without_boundaries_is_a_label_of_negatives(reviewed_empty, tmp_path):
    from csboundary.models.training.data import TrainingCity
    from csboundary.pipeline.training.labelled_inputs import labelled_cities

    [city] = labelled_cities([reviewed_empty], tmp_path / "work")
    assert read_ground_truth(city_layout.ground_truth_path(city)).empty
    with TrainingCity(city) as training:
        assert (
            len(training.labels.boundaries) == 0
            and len(training.labels.keypoints) == 0
            and training.labels.bounds.shape[0] == 0
        )
        _, targets, valid = training.fpn_sample(PixelWindow(0, 0, SIZE, SIZE))
        assert valid[:, :150].all() and not valid[:, 150:].any()  # known, as negatives, inside the complete area only
        assert not targets.any()
        assert training.gt_vertices(PixelWindow(0, 0, SIZE, SIZE)).shape == (0, 2)
        assert training.adjacency(np.array([[10.0, 10.0], [100.0, 100.0]]), PixelWindow(0, 0, SIZE, SIZE)).sum() == 0


def test_ground_truth_that_is_empty_without_an_area_or_off_the_tiles_is_still_refused(tmp_path):
    from csboundary.data.user_city import make_city

    tile = write_geotiff(
        tmp_path / "tiles" / "t.tif", np.zeros((4, 64, 64), np.uint8), Affine(0.3, 0, 500000, 0, -0.3, 4400000), UTM
    )
    gpd.GeoDataFrame(geometry=gpd.GeoSeries([], crs=UTM), crs=UTM).to_file(
        tmp_path / "empty.gpkg", driver="GPKG", engine="pyogrio"
    )
    one_error(
        run_cli(
            "make-city", str(tile), "--ground-truth", str(tmp_path / "empty.gpkg"), "--out", str(tmp_path / "city")
        ),
        str(tmp_path / "empty.gpkg"),
        "holds no road boundaries",
    )
    assert not (tmp_path / "city").exists()
    far = gpd.GeoDataFrame(geometry=[LineString([(600000.0, 4300000.0), (600010.0, 4300000.0)])], crs=UTM)
    far.to_file(tmp_path / "far.gpkg", driver="GPKG", engine="pyogrio")
    area = gpd.GeoDataFrame(geometry=[box(500000, 4399981, 500019, 4400000)], crs=UTM)
    with pytest.raises(
        InputError, match="no boundary lies on the tiles"
    ):  # a complete area does not excuse a wrong CRS
        make_city([tile], tmp_path / "far.gpkg", tmp_path / "city", complete=area)
    assert not (tmp_path / "city").exists()
