"""The city pipeline's GDAL environment gives GDAL a block cache of the intended size."""

import pytest
import rasterio

from csboundary.pipeline.prediction.city_job import GDAL_CACHE_MB, GDAL_ENV

get_gdal_config = pytest.importorskip("rasterio._env").get_gdal_config


def test_block_cache_is_megabytes_not_bytes():
    """rasterio passes an integer GDAL_CACHEMAX to GDAL as bytes: a bare 128 would leave GDAL a
    128-byte cache, and every overlapped window would decode its compressed blocks again."""
    with rasterio.Env(**GDAL_ENV):
        assert get_gdal_config("GDAL_CACHEMAX") == GDAL_CACHE_MB * 2**20
    with rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB):  # the trap this guards against
        assert get_gdal_config("GDAL_CACHEMAX") == GDAL_CACHE_MB
