"""Mosaic opening, validation and windowed reading (csboundary.data.raster and .raster_files), plus
the GeoTIFF writer and the atomic writer it relies on."""

from __future__ import annotations

import os
import random
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine
from conftest import CRS, GSD, ORIGIN, TILE_H, TILE_W
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from csboundary.data.atomic import atomic_path
from csboundary.data.geotiff import BAND_NAMES, write_geotiff
from csboundary.data.raster import Mosaic
from csboundary.data.raster_files import find_rasters
from csboundary.data.windows import PixelWindow
from csboundary.errors import InputError, InputWarning
from csboundary.pipeline.prediction.options import PredictionOptions

X0, Y0 = ORIGIN


def padded_truth(full: np.ndarray, window: PixelWindow) -> tuple[np.ndarray, np.ndarray]:
    """What reading ``window`` must return: ``full`` cut out with zeros outside, and the inside mask."""
    bands, h, w = full.shape
    data = np.zeros((bands, window.height, window.width), dtype=full.dtype)
    valid = np.zeros((window.height, window.width), dtype=bool)
    for r in range(window.height):
        for c in range(window.width):
            mr, mc = window.row_off + r, window.col_off + c
            if 0 <= mr < h and 0 <= mc < w:
                data[:, r, c] = full[:, mr, mc]
                valid[r, c] = True
    return data, valid


def assert_names(err: InputError, path: Path) -> None:
    assert err.path == str(path)
    assert str(err).startswith(f"{path}: ")
    assert "\n" not in str(err)


def tile_transform(col_px: float, row_px: float, gsd: float = GSD) -> Affine:
    """Transform of a tile whose top-left sits at mosaic pixel (col_px, row_px) of the default grid."""
    return Affine(gsd, 0.0, X0 + col_px * GSD, 0.0, -gsd, Y0 - row_px * GSD)


def rand_img(bands=4, h=TILE_H, w=TILE_W, dtype=np.uint8, seed=1) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, size=(bands, h, w)).astype(dtype)


# -- opening ---------------------------------------------------------------------------------------


def test_open_directory_places_tiles(tiles):
    with Mosaic.open(tiles.directory) as m:
        assert (m.width, m.height) == (120, 80)
        assert m.crs == rasterio.crs.CRS.from_string(CRS)
        assert m.transform == Affine(0.5, 0.0, X0, 0.0, -0.5, Y0)
        assert m.gsd == 0.5
        assert m.bounds == (X0, Y0 - 40.0, X0 + 60.0, Y0)
        placed = {t.path.name: t.window for t in m.tiles}
        assert placed == {
            "tile_r0_c0.tif": PixelWindow(0, 0, 60, 40),
            "tile_r0_c1.tif": PixelWindow(60, 0, 60, 40),
            "tile_r1_c0.tif": PixelWindow(0, 40, 60, 40),
            "tile_r1_c1.tif": PixelWindow(60, 40, 60, 40),
        }
        assert all(t.band_count == 4 and t.dtype == "uint8" for t in m.tiles)
        assert "4 tiles" in repr(m) and "120x80" in repr(m)


def test_open_list_of_files_in_any_order(tiles):
    paths = list(tiles.paths)
    random.Random(3).shuffle(paths)
    with Mosaic.open(paths) as m:
        assert (m.width, m.height) == (120, 80)
        assert m.transform == tiles.transform
        r = m.read(m.window)
        np.testing.assert_array_equal(r.data, tiles.full)
        assert r.valid.all()


def test_open_partial_list_uses_its_own_origin(tiles):
    """Only the right-hand column: the mosaic starts 60 px (30 m) east of the full one."""
    with Mosaic.open([str(tiles.tile_path(0, 1)), tiles.tile_path(1, 1)]) as m:
        assert (m.width, m.height) == (60, 80)
        assert m.transform == Affine(0.5, 0.0, X0 + 30.0, 0.0, -0.5, Y0)
        np.testing.assert_array_equal(m.read(m.window).data, tiles.full[:, :, 60:])


def test_open_single_file(tiles):
    path = tiles.tile_path(1, 0)
    with Mosaic.open(path) as m:
        assert (m.width, m.height) == (60, 40)
        assert m.transform == Affine(0.5, 0.0, X0, 0.0, -0.5, Y0 - 20.0)
        np.testing.assert_array_equal(m.read(m.window).data, tiles.full[:, 40:, :60])
    with Mosaic.open(str(path)) as m:  # a str works as well as a Path
        assert (m.width, m.height) == (60, 40)


def test_directory_is_searched_recursively_and_ignores_other_files(tiles):
    sub = tiles.directory / "south"
    sub.mkdir()
    for r_c in [(1, 0), (1, 1)]:
        p = tiles.tile_path(*r_c)
        p.rename(sub / p.name)
    (tiles.directory / "README.txt").write_text("not a raster, not a .tif")
    (tiles.directory / ".tile.partial-123.tif").write_text("half-written leftover of an atomic writer")
    found = find_rasters(tiles.directory)
    assert sorted(p.name for p in found) == sorted(p.name for p in tiles.paths)
    with Mosaic.open(tiles.directory) as m:
        np.testing.assert_array_equal(m.read(m.window).data, tiles.full)


def test_gap_between_tiles_is_invalid(tiles):
    """Diagonal tiles only: the two missing quadrants read as zeros and invalid."""
    with Mosaic.open([tiles.tile_path(0, 0), tiles.tile_path(1, 1)]) as m:
        assert (m.width, m.height) == (120, 80)
        r = m.read(m.window)
    expected_valid = np.zeros((80, 120), dtype=bool)
    expected_valid[:40, :60] = True
    expected_valid[40:, 60:] = True
    np.testing.assert_array_equal(r.valid, expected_valid)
    np.testing.assert_array_equal(r.data, np.where(expected_valid, tiles.full, 0))


# -- reading ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "window",
    [
        PixelWindow(50, 30, 20, 20),  # across all four tiles
        PixelWindow(55, 0, 10, 40),  # across the vertical border only
        PixelWindow(0, 39, 120, 2),  # across the horizontal border, full width
        PixelWindow(60, 40, 1, 1),  # first pixel of the last tile
        PixelWindow(59, 39, 2, 2),  # one pixel from each tile
        PixelWindow(0, 0, 120, 80),  # everything
    ],
)
def test_window_across_tile_borders_equals_stitched_array(shared_tiles, window):
    with Mosaic.open(shared_tiles.directory) as m:
        r = m.read(window)
    assert r.window == window
    assert r.data.dtype == np.uint8
    assert r.data.shape == (4, window.height, window.width)
    np.testing.assert_array_equal(r.data, shared_tiles.full[(slice(None), *window.slices())])
    assert r.valid.all()


def test_window_across_mosaic_edge_is_zero_padded(shared_tiles):
    window = PixelWindow(-5, -3, 10, 8)  # 5 cols left of, 3 rows above the mosaic
    with Mosaic.open(shared_tiles.directory) as m:
        r = m.read(window)
    expected_valid = np.zeros((8, 10), dtype=bool)
    expected_valid[3:, 5:] = True
    np.testing.assert_array_equal(r.valid, expected_valid)
    assert not r.data[:, :3, :].any() and not r.data[:, :, :5].any()
    np.testing.assert_array_equal(r.data[:, 3:, 5:], shared_tiles.full[:, 0:5, 0:5])


def test_window_beyond_bottom_right_and_fully_outside(shared_tiles):
    with Mosaic.open(shared_tiles.directory) as m:
        r = m.read(PixelWindow(110, 75, 20, 10))
        outside = m.read(PixelWindow(200, -50, 7, 6))
        empty = m.read(PixelWindow(10, 10, 0, 5))
    assert r.valid[:5, :10].all() and not r.valid[5:, :].any() and not r.valid[:, 10:].any()
    np.testing.assert_array_equal(r.data[:, :5, :10], shared_tiles.full[:, 75:, 110:])
    assert r.data[:, 5:, :].sum() == 0 and r.data[:, :, 10:].sum() == 0
    assert outside.data.shape == (4, 6, 7) and not outside.data.any() and not outside.valid.any()
    assert empty.data.shape == (4, 5, 0) and empty.valid.shape == (5, 0)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    col=st.integers(-40, 130),
    row=st.integers(-40, 90),
    width=st.integers(0, 70),
    height=st.integers(0, 60),
)
def test_any_window_matches_padded_truth(shared_tiles, col, row, width, height):
    window = PixelWindow(col, row, width, height)
    with Mosaic.open(shared_tiles.directory) as m:
        r = m.read(window)
    data, valid = padded_truth(shared_tiles.full, window)
    np.testing.assert_array_equal(r.valid, valid)
    np.testing.assert_array_equal(r.data, data)


def test_read_world_equals_pixel_read(shared_tiles):
    window = PixelWindow(50, 30, 20, 20)
    # by hand: x = X0 + 0.5 col, y = Y0 - 0.5 row
    minx, maxx = X0 + 25.0, X0 + 35.0
    maxy, miny = Y0 - 15.0, Y0 - 25.0
    with Mosaic.open(shared_tiles.directory) as m:
        assert m.window_from_bounds(minx, miny, maxx, maxy) == window
        a, b = m.read_world(minx, miny, maxx, maxy), m.read(window)
        # a rectangle not on pixel edges needs the same pixels (rounded outwards)
        c = m.read_world(minx + 0.1, miny + 0.2, maxx - 0.1, maxy - 0.2)
        # a rectangle partly outside the mosaic (west of it) reads padded
        d = m.read_world(X0 - 2.0, miny, X0 + 3.0, maxy)
    assert a.window == window and c.window == window
    np.testing.assert_array_equal(a.data, b.data)
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(c.data, b.data)
    assert d.window == PixelWindow(-4, 30, 10, 20)
    np.testing.assert_array_equal(d.valid[:, :4], False)
    np.testing.assert_array_equal(d.data[:, :, 4:], shared_tiles.full[:, 30:50, 0:6])


def test_world_pixel_conversions_of_mosaic(shared_tiles):
    with Mosaic.open(shared_tiles.directory) as m:
        xs, ys = m.pixel_to_world([0, 120, 60.5], [0, 80, 40.5])
        np.testing.assert_allclose(xs, [X0, X0 + 60.0, X0 + 30.25])
        np.testing.assert_allclose(ys, [Y0, Y0 - 40.0, Y0 - 20.25])
        cols, rows = m.world_to_pixel(xs, ys)
        np.testing.assert_allclose(cols, [0, 120, 60.5], atol=1e-6)
        np.testing.assert_allclose(rows, [0, 80, 40.5], atol=1e-6)


# -- bad input: every problem is an InputError naming the file -------------------------------------


def test_text_file_named_tif(tiles):
    bad = tiles.directory / "zz_notes.tif"
    bad.write_text("this is not a GeoTIFF\n")
    with pytest.raises(InputError) as exc:
        Mosaic.open(tiles.directory)
    assert_names(exc.value, bad)
    assert "not a raster" in exc.value.problem


def test_missing_file(tiles, tmp_path):
    missing = tmp_path / "nowhere" / "missing.tif"
    with pytest.raises(InputError) as exc:
        Mosaic.open([tiles.tile_path(0, 0), missing])
    assert_names(exc.value, missing)
    assert "not found" in exc.value.problem


def test_two_band_file(tmp_path, write_tif):
    path = write_tif(tmp_path / "two.tif", rand_img(bands=2), tile_transform(0, 0))
    with pytest.raises(InputError) as exc:
        Mosaic.open(path)
    assert_names(exc.value, path)
    assert "2 band" in exc.value.problem


def test_mixed_crs(tiles, write_tif):
    other = write_tif(tiles.directory / "tile_r2_c0.tif", rand_img(), tile_transform(0, 80), crs="EPSG:32617")
    with pytest.raises(InputError) as exc:
        Mosaic.open(tiles.directory)
    assert_names(exc.value, other)
    assert "CRS" in exc.value.problem and "32617" in exc.value.problem


def test_crs_and_no_crs_mixed(tiles, write_tif):
    other = write_tif(tiles.directory / "tile_r2_c0.tif", rand_img(), tile_transform(0, 80), crs=None)
    with pytest.raises(InputError) as exc:
        Mosaic.open(tiles.directory)
    assert_names(exc.value, other)
    assert "CRS" in exc.value.problem


def test_mixed_resolution(tiles, write_tif):
    other = write_tif(tiles.directory / "tile_r2_c0.tif", rand_img(), tile_transform(0, 80, gsd=1.0))
    with pytest.raises(InputError) as exc:
        Mosaic.open(tiles.directory)
    assert_names(exc.value, other)
    assert "pixel size" in exc.value.problem


def test_mixed_dtype(tiles, write_tif):
    other = write_tif(tiles.directory / "tile_r2_c0.tif", rand_img(dtype=np.uint16), tile_transform(0, 80))
    with pytest.raises(InputError) as exc:
        Mosaic.open(tiles.directory)
    assert_names(exc.value, other)
    assert "uint16" in exc.value.problem


@pytest.mark.parametrize(
    "col_px,row_px",
    [
        (120.5, 0),  # east of the mosaic, half a pixel off in x
        (0, 80.5),  # south of the mosaic, half a pixel off in y
        (-60.5, 0),  # west of every other tile: the misaligned tile defines the mosaic's west edge
        (0, -40.5),  # north of every other tile
    ],
)
def test_misaligned_tile(tiles, write_tif, col_px, row_px):
    bad = write_tif(tiles.directory / "zz_shifted.tif", rand_img(), tile_transform(col_px, row_px))
    with pytest.raises(InputError) as exc:
        Mosaic.open(tiles.directory)
    assert_names(exc.value, bad)
    assert "not aligned" in exc.value.problem
    assert str(tiles.tile_path(0, 0)) in exc.value.problem  # names the grid it was compared with


def test_whole_pixel_offsets_are_aligned(tiles, write_tif):
    """A tile a whole number of pixels away (even overhanging) is placed, not rejected."""
    extra = rand_img(seed=7)
    write_tif(tiles.directory / "zz_extra.tif", extra, tile_transform(-7, 85))
    with Mosaic.open(tiles.directory) as m:
        assert (m.width, m.height) == (127, 125)
        assert m.transform == Affine(0.5, 0.0, X0 - 3.5, 0.0, -0.5, Y0)
        placed = {t.path.name: t.window for t in m.tiles}
        assert placed["zz_extra.tif"] == PixelWindow(0, 85, 60, 40)
        assert placed["tile_r0_c0.tif"] == PixelWindow(7, 0, 60, 40)
        np.testing.assert_array_equal(m.read(PixelWindow(0, 85, 60, 40)).data, extra)
        np.testing.assert_array_equal(m.read(PixelWindow(7, 0, 120, 80)).data, tiles.full)


def test_empty_directory(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no rasters here")
    with pytest.raises(InputError) as exc:
        Mosaic.open(empty)
    assert_names(exc.value, empty)
    assert "no raster" in exc.value.problem


def test_empty_list():
    with pytest.raises(InputError, match="no input rasters"):
        Mosaic.open([])


def test_rotated_georeference_rejected(tmp_path, write_tif):
    path = write_tif(tmp_path / "rot.tif", rand_img(), Affine(0.5, 0.1, X0, 0.1, -0.5, Y0))
    with pytest.raises(InputError) as exc:
        Mosaic.open(path)
    assert_names(exc.value, path)
    assert "north-up" in exc.value.problem


# -- band and georeference fallbacks ---------------------------------------------------------------


def test_three_band_file_warns_and_fills_nir_with_green(tmp_path, write_tif):
    rgb = rand_img(bands=3)
    path = write_tif(tmp_path / "rgb.tif", rgb, tile_transform(0, 0))
    with pytest.warns(InputWarning, match="3-band") as record:
        m = Mosaic.open(path)
    assert any(str(path) in str(w.message) for w in record)
    with m:
        r = m.read(PixelWindow(-2, 5, 30, 20))
    assert r.data.shape == (4, 20, 30)
    np.testing.assert_array_equal(r.data[:3, :, 2:], rgb[:, 5:25, :28])
    np.testing.assert_array_equal(r.data[3], r.data[1])  # NIR == green, also in the padding
    np.testing.assert_array_equal(r.data[3, :, 2:], rgb[1, 5:25, :28])
    assert not r.valid[:, :2].any() and r.valid[:, 2:].all()


def test_three_and_four_band_tiles_mix(tiles, write_tif):
    rgb = rand_img(bands=3, seed=5)
    write_tif(tiles.directory / "tile_r2_c0.tif", rgb, tile_transform(0, 80))
    with pytest.warns(InputWarning):
        m = Mosaic.open(tiles.directory)
    with m:
        r = m.read(PixelWindow(0, 70, 60, 20))  # 10 rows of a 4-band tile, 10 rows of the RGB one
    np.testing.assert_array_equal(r.data[:, :10], tiles.full[:, 70:80, :60])
    np.testing.assert_array_equal(r.data[:3, 10:], rgb[:, :10, :])
    np.testing.assert_array_equal(r.data[3, 10:], rgb[1, :10, :])


def test_five_band_file_warns_and_uses_first_four(tmp_path, write_tif):
    img = rand_img(bands=5)
    path = write_tif(tmp_path / "five.tif", img, tile_transform(0, 0))
    with pytest.warns(InputWarning, match="5 bands"):
        m = Mosaic.open(path)
    with m:
        np.testing.assert_array_equal(m.read(m.window).data, img[:4])


def test_no_crs_warns_and_uses_pixel_coordinates(tmp_path, write_tif):
    img = rand_img()
    path = write_tif(tmp_path / "plain.tif", img, transform=None, crs=None)
    with pytest.warns(InputWarning, match="no CRS") as record:
        m = Mosaic.open(path)
    assert any(str(path) in str(w.message) for w in record)
    with m:
        assert m.crs is None
        assert m.transform == Affine.identity()
        xs, ys = m.pixel_to_world([0, 10.5], [0, 3.25])
        np.testing.assert_array_equal(xs, [0, 10.5])
        np.testing.assert_array_equal(ys, [0, 3.25])
        assert m.window_from_bounds(2, 3, 12, 8) == PixelWindow(2, 3, 10, 5)
        np.testing.assert_array_equal(m.read(m.window).data, img)
        np.testing.assert_array_equal(m.read_world(2, 3, 12, 8).data, img[:, 3:8, 2:12])


def test_several_tiles_without_any_georeference_rejected(tmp_path, write_tif):
    a = write_tif(tmp_path / "a.tif", rand_img(), transform=None, crs=None)
    b = write_tif(tmp_path / "b.tif", rand_img(), transform=None, crs=None)
    with pytest.raises(InputError) as exc:
        Mosaic.open([a, b])
    assert_names(exc.value, b)


# -- invalid pixels --------------------------------------------------------------------------------


def test_float_nan_areas_are_invalid_and_zero(tmp_path, write_tif):
    img = np.random.default_rng(2).uniform(0.1, 1.0, size=(4, 40, 60)).astype(np.float32)
    img[:, 5:10, 20:30] = np.nan  # a NaN hole in every band
    img[2, 30, 40] = np.nan  # NaN in one band only also invalidates the pixel
    expected_valid = np.ones((40, 60), dtype=bool)
    expected_valid[5:10, 20:30] = False
    expected_valid[30, 40] = False
    path = write_tif(tmp_path / "float.tif", img, tile_transform(0, 0))
    with Mosaic.open(path) as m:
        r = m.read(PixelWindow(-1, 0, 62, 41))
    assert r.data.dtype == np.float32
    assert np.isfinite(r.data).all()
    inner_valid = r.valid[:40, 1:61]
    np.testing.assert_array_equal(inner_valid, expected_valid)
    assert not r.valid[40].any() and not r.valid[:, 0].any() and not r.valid[:, 61].any()
    np.testing.assert_array_equal(r.data[:, :40, 1:61], np.where(expected_valid, img, 0))
    assert (r.data[:, ~r.valid] == 0).all()


def test_uint8_nodata_pixels_are_invalid(tmp_path, write_tif):
    img = np.random.default_rng(3).integers(1, 256, size=(4, 40, 60)).astype(np.uint8)
    img[:, 12:20, 0:15] = 0  # nodata in every band
    img[:, 39, 59] = 0
    img[0, 2, 2] = 0  # only red is 0: a real dark-red pixel, still data (GDAL's per-dataset mask)
    path = write_tif(tmp_path / "nodata.tif", img, tile_transform(0, 0), nodata=0)
    expected_valid = np.ones((40, 60), dtype=bool)
    expected_valid[12:20, 0:15] = False
    expected_valid[39, 59] = False
    with Mosaic.open(path) as m:
        r = m.read(m.window)
    np.testing.assert_array_equal(r.valid, expected_valid)
    np.testing.assert_array_equal(r.data, img)  # nodata pixels already hold 0


def test_uint8_nonzero_nodata_value_is_zeroed(tmp_path, write_tif):
    img = np.random.default_rng(4).integers(0, 255, size=(4, 40, 60)).astype(np.uint8)  # never 255
    img[:, 0:3, :] = 255
    path = write_tif(tmp_path / "nodata255.tif", img, tile_transform(0, 0), nodata=255)
    with Mosaic.open(path) as m:
        r = m.read(m.window)
    assert not r.valid[0:3].any() and r.valid[3:].all()
    assert not r.data[:, 0:3].any()  # invalid pixels are set to 0, not left at 255
    np.testing.assert_array_equal(r.data[:, 3:], img[:, 3:])


def test_nir_of_zero_is_data_although_gdal_flags_band4_as_alpha(tmp_path, write_tif):
    """rasterio/GDAL write 4-band uint8 GeoTIFFs as RGBA by default; band 4 is still NIR, and a NIR
    of 0 (open water) must not make a pixel invalid."""
    img = np.random.default_rng(6).integers(1, 256, size=(4, 40, 60)).astype(np.uint8)
    img[3, 10:30, 5:50] = 0  # a lake: no NIR reflectance
    img[3, 0, :] = 128
    path = write_tif(tmp_path / "rgbn.tif", img, tile_transform(0, 0))
    with rasterio.open(path) as ds:  # precondition: the file really carries the alpha flag
        assert ds.colorinterp[3] == rasterio.enums.ColorInterp.alpha
    with Mosaic.open(path) as m:
        r = m.read(m.window)
    assert r.valid.all()
    np.testing.assert_array_equal(r.data, img)


# -- writing ---------------------------------------------------------------------------------------


def test_write_geotiff_valid_mask_round_trips(tmp_path):
    rng = np.random.default_rng(9)
    img = rng.integers(0, 256, size=(4, 40, 60), dtype=np.uint8)
    valid = np.ones((40, 60), dtype=bool)
    valid[10:25, 30:55] = False
    valid[0, 0] = False
    valid[39, :] = False
    transform = tile_transform(0, 0)
    path = write_geotiff(tmp_path / "out" / "w.tif", img, transform, CRS, valid=valid, tags={"source": "test"})
    assert path == tmp_path / "out" / "w.tif"
    assert os.listdir(tmp_path / "out") == ["w.tif"]  # no temporary left behind
    with Mosaic.open(path) as m:
        assert m.transform == transform
        assert m.crs == rasterio.crs.CRS.from_string(CRS)
        r = m.read(m.window)
    np.testing.assert_array_equal(r.valid, valid)
    np.testing.assert_array_equal(r.data, np.where(valid, img, 0))
    with rasterio.open(path) as ds:
        assert ds.descriptions == BAND_NAMES
        assert ds.tags()["source"] == "test"
        np.testing.assert_array_equal(ds.read(), img)  # masked pixels keep their stored values


def test_write_geotiff_without_mask_is_all_valid(tmp_path):
    img = np.random.default_rng(10).integers(0, 256, size=(4, 40, 60), dtype=np.uint8)
    path = write_geotiff(tmp_path / "plain.tif", img, tile_transform(0, 0), CRS)
    with Mosaic.open(path) as m:
        r = m.read(m.window)
    assert r.valid.all()
    np.testing.assert_array_equal(r.data, img)


def test_write_geotiff_rejects_2d_image(tmp_path):
    with pytest.raises(ValueError, match="bands, rows, cols"):
        write_geotiff(tmp_path / "x.tif", np.zeros((40, 60), np.uint8), tile_transform(0, 0), CRS)
    assert not (tmp_path / "x.tif").exists()


def test_atomic_writer_leaves_nothing_when_block_raises(tmp_path):
    final = tmp_path / "sub" / "result.tif"
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_path(final) as tmp:
            assert tmp.parent == final.parent and tmp.suffix == ".tif" and tmp != final
            tmp.write_bytes(b"half a file")
            raise RuntimeError("boom")
    assert not final.exists()
    assert os.listdir(final.parent) == []


def test_atomic_writer_keeps_old_file_when_block_raises(tmp_path):
    final = tmp_path / "result.gpkg"
    final.write_text("previous complete result")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(final) as tmp:
            tmp.write_text("new, incomplete")
            raise KeyboardInterrupt
    assert final.read_text() == "previous complete result"
    assert os.listdir(tmp_path) == ["result.gpkg"]


def test_atomic_writer_renames_on_success(tmp_path):
    final = tmp_path / "result.txt"
    final.write_text("old")
    with atomic_path(final) as tmp:
        tmp.write_text("new")
        assert final.read_text() == "old"  # not visible before the block ends
    assert final.read_text() == "new"
    assert os.listdir(tmp_path) == ["result.txt"]


def test_write_geotiff_failure_leaves_no_file(tmp_path, monkeypatch):
    """A writer crashing half-way (here: while writing the mask) leaves no file under the final name."""

    def explode(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(rasterio.io.DatasetWriter, "write_mask", explode)
    img = np.zeros((4, 40, 60), np.uint8)
    with pytest.raises(OSError, match="disk full"):
        write_geotiff(tmp_path / "w.tif", img, tile_transform(0, 0), CRS, valid=np.ones((40, 60), bool))
    assert os.listdir(tmp_path) == []


def test_a_reduced_read_is_the_block_mean_across_tiles(shared_tiles):
    t = shared_tiles
    with Mosaic.open(t.directory) as mosaic:
        small = mosaic.read(mosaic.window, scale=0.5)
        corner = mosaic.read(PixelWindow(50, 30, 20, 20), scale=0.5)  # straddles all four tiles
    h, w = t.full.shape[1] // 2, t.full.shape[2] // 2
    mean = t.full.astype(float).reshape(4, h, 2, w, 2).mean(axis=(2, 4))
    assert small.data.shape == (4, h, w) and small.valid.all()
    assert np.abs(small.data - mean).max() <= 0.5  # the block average, rounded to uint8 (band 4 never alpha)
    assert np.abs(corner.data.astype(float) - mean[:, 15:25, 25:35]).max() <= 0.5
    with Mosaic.open(t.directory) as mosaic:  # strips of 10 rows stitch into the same picture
        assert np.array_equal(mosaic._read_reduced(mosaic.window, 0.5, strip_pixels=10 * mosaic.width).data, small.data)


def test_band_four_holding_only_0_and_255_is_alpha_not_nir(tmp_path):
    import rasterio
    from rasterio.enums import ColorInterp

    rgb = np.random.default_rng(0).integers(0, 256, (3, 40, 40), dtype=np.uint8)
    alpha = np.full((1, 40, 40), 255, np.uint8)
    alpha[0, :, :10] = 0  # a transparent strip
    path = tmp_path / "rgba.tif"
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=40,
        height=40,
        count=4,
        dtype="uint8",
        crs="EPSG:32618",
        transform=Affine(0.15, 0, 500000, 0, -0.15, 4400000),
    ) as ds:
        ds.write(np.concatenate([rgb, alpha]))
        ds.colorinterp = [ColorInterp.red, ColorInterp.green, ColorInterp.blue, ColorInterp.alpha]
    with pytest.warns(InputWarning, match="RGB \\+ alpha"):
        mosaic = Mosaic.open(path)
    with mosaic:
        read = mosaic.read(mosaic.window)
    assert not read.valid[:, :10].any() and read.valid[:, 10:].all()  # alpha is the validity
    assert np.array_equal(read.data[3, :, 10:], rgb[1, :, 10:])  # NIR := green, never the alpha band


def test_open_files_stay_under_the_cap_and_reads_do_not_change(shared_tiles):
    with Mosaic.open(shared_tiles.directory) as reference:
        expected = reference.read(reference.window).data
    with Mosaic.open(shared_tiles.directory) as mosaic:
        mosaic.max_open = 2  # four tiles, two handles at most
        for _ in range(2):
            for window in (
                PixelWindow(0, 0, 30, 20),
                PixelWindow(70, 50, 30, 20),
                PixelWindow(0, 50, 30, 20),
                PixelWindow(70, 0, 30, 20),
            ):
                mosaic.read(window)
                assert len(mosaic._handles) <= 2
        assert np.array_equal(mosaic.read(mosaic.window).data, expected)


def test_patches_without_imagery_skip_the_model(tmp_path):
    from csboundary.data.grid import GridConfig
    from csboundary.graph import BoundaryGraph
    from csboundary.graph.settings import GraphSettings
    from csboundary.pipeline.prediction.city import predict_city

    data = np.full((4, 100, 100), 90, np.uint8)
    for name, x0 in (("west.tif", 500000.0), ("east.tif", 500000.0 + 400 * 0.5)):  # 300 px of nothing between
        write_geotiff(tmp_path / name, data, Affine(0.5, 0, x0, 0, -0.5, 4400000), "EPSG:32618")

    class Counting:
        seen = 0
        settings, confidence, collect_evidence = GraphSettings(), None, False

        def patch_maps(self, patches, images):
            self.seen += len(images)
            return [np.zeros((2, *i.shape[1:]), np.float32) for i in images]

        def extract(self, maps):
            return BoundaryGraph(np.zeros((0, 2)), np.zeros((0, 2), np.int64))

        def connect(self, patch, image, maps, found):
            return found

    model = Counting()
    with Mosaic.open(tmp_path) as mosaic:
        result = predict_city(mosaic, model, PredictionOptions(grid=GridConfig(core=100, margin=10), progress=False))
    # windows of 120 px (cores 100 + 10 px margins): only the middle one (cols 190-310) sees no tile; 300 px apart, the
    # tiles are one group (data/footprint.py), so every patch between them is planned as before
    assert result.n_patches == 5 and result.patches_without_imagery == 1 and model.seen == 4


def test_area_reduced_averages_blocks_of_each_band_and_keeps_half_valid_areas():
    """4x4 -> 2x2: every output pixel is its 2x2 block's mean (bands apart, from a strided view),
    valid where at least two of the block's four pixels were."""
    from csboundary.data.raster import area_reduced

    bands = np.zeros((2, 6, 6), np.uint8)
    bands[0, 1:5, 1:5] = [[0, 4, 8, 8], [4, 8, 8, 8], [100, 100, 2, 2], [100, 100, 2, 6]]
    bands[1, 1:5, 1:5] = 200
    valid = np.zeros((6, 6), bool)
    valid[1:3, 1:3] = [[True, True], [False, False]]  # half of the top-left block
    valid[3:5, 3:5] = [[True, False], [False, False]]  # a quarter of the bottom-right one
    pixels, kept = area_reduced(bands[:, 1:5, 1:5], valid[1:5, 1:5], 2, 2)
    assert pixels.dtype == np.uint8 and pixels.shape == (2, 2, 2)
    assert pixels[0].tolist() == [[4, 8], [100, 3]]
    assert (pixels[1] == 200).all()
    assert kept.tolist() == [[True, False], [False, False]]
