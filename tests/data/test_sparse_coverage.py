"""A sparse GeoTIFF (blocks outside the data never written) is known empty there without reading."""

from __future__ import annotations

import json

import numpy as np
import rasterio
from rasterio.transform import from_origin
from rasterio.windows import Window

from csboundary.data.raster import Mosaic
from csboundary.data.raster_files import written_blocks
from csboundary.data.windows import PixelWindow


def sparse_tif(path, size=4096, data_px=1000, sparse=True):
    profile = dict(
        driver="GTiff",
        count=4,
        dtype="uint8",
        width=size,
        height=size,
        tiled=True,
        blockxsize=512,
        blockysize=512,
        compress="deflate",
        nodata=0,
        crs="EPSG:32618",
        transform=from_origin(500000, 4500000, 0.152, 0.152),
    )
    if sparse:
        profile["SPARSE_OK"] = True
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(np.full((4, data_px, data_px), 9, np.uint8), window=Window(0, 0, data_px, data_px))
    return path


def test_written_blocks_are_those_under_the_data(tmp_path):
    with rasterio.open(sparse_tif(tmp_path / "s.tif")) as ds:
        blocks, shape = written_blocks(ds)
    assert shape == (512, 512) and blocks.shape == (8, 8)
    assert blocks[:2, :2].all() and blocks.sum() == 4  # 1000 px of data: blocks 0 and 1 each way


def test_a_window_over_unwritten_blocks_has_no_data_and_reads_as_nodata(tmp_path):
    with Mosaic.open(sparse_tif(tmp_path / "s.tif")) as mosaic:
        assert mosaic.may_have_data(PixelWindow(0, 0, 1100, 1100))
        assert mosaic.may_have_data(PixelWindow(1023, 1023, 10, 10))  # still in block 1
        assert not mosaic.may_have_data(PixelWindow(1024, 0, 1100, 1100))
        assert not mosaic.may_have_data(PixelWindow(2000, 2000, 1100, 1100))
        empty = mosaic.read(PixelWindow(2000, 2000, 1100, 1100))
        assert not empty.valid.any() and not empty.data.any()
        full = mosaic.read(PixelWindow(0, 0, 1100, 1100))
        assert full.valid.sum() == 1000 * 1000 and (full.data[:, :1000, :1000] == 9).all()


def test_a_dense_file_is_never_taken_for_empty(tmp_path):
    # every block written (zeros compress but exist): nothing is known empty, so everything is read
    with Mosaic.open(sparse_tif(tmp_path / "d.tif", sparse=False)) as mosaic:
        assert mosaic.may_have_data(PixelWindow(2000, 2000, 1100, 1100))


def test_predict_warns_of_a_sparse_mosaic_before_it_starts(tmp_path):
    from helpers import run_cli

    path = sparse_tif(tmp_path / "s.tif", size=5000)
    done = run_cli("predict", str(path), "--out", str(tmp_path / "out"), "--device", "cpu", "--quiet")
    assert done.returncode == 0, done.stderr
    said = [line for line in done.stderr.splitlines() if "imagery covers" in line]
    assert len(said) == 1 and said[0].startswith("warning: ") and "4 of 25 patches" in said[0], done.stderr
    # only the 4 patches over the data are read and predicted; only the 3 x 3 windows around them are connected
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["work"]["patches_predicted"] == 4 and summary["work"]["windows_connected"] == 9
    assert summary["patches_without_imagery"] == 21


def test_a_truncated_geotiff_is_refused_before_any_work(tmp_path):
    from helpers import run_cli

    path = tmp_path / "cut.tif"
    profile = dict(
        driver="GTiff",
        count=4,
        dtype="uint8",
        width=2000,
        height=2000,
        tiled=True,
        blockxsize=512,
        blockysize=512,
        compress="deflate",
        crs="EPSG:32618",
        transform=from_origin(500000, 4500000, 0.152, 0.152),
    )
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(np.random.default_rng(0).integers(0, 255, (4, 2000, 2000), dtype=np.uint8))
    with open(path, "r+b") as f:
        f.truncate(path.stat().st_size // 2)
    done = run_cli("predict", str(path), "--out", str(tmp_path / "out"), "--device", "cpu", "--quiet")
    lines = [line for line in done.stderr.strip().splitlines() if not line.startswith("warning:")]
    assert done.returncode == 2 and len(lines) == 1 and "cut.tif" in lines[0] and "truncated" in lines[0], done.stderr
    assert not (tmp_path / "out").exists()  # no run store left to block the next run once the file is fixed
