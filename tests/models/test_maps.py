"""Mosaic-wide FPN maps: overlapping patch predictions are averaged (paper IV-E)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.geotiff import write_geotiff
from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.data.nodata import fill_nodata
from csboundary.data.raster import Mosaic
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.maps import predict_mosaic_maps, predict_probabilities


def test_overlaps_are_the_mean_of_the_patches_covering_them(tmp_path):
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (4, 96, 160), dtype=np.uint8)
    write_geotiff(tmp_path / "t.tif", image, Affine(0.5, 0, 0, 0, -0.5, 48), "EPSG:32618")
    model = FPN(FPNConfig(widths=(8, 8, 8, 8), blocks=(1, 1, 1, 1), pyramid=8, stem=8)).eval()
    with Mosaic.open(tmp_path / "t.tif") as mosaic:
        grid = PatchGrid.for_mosaic(mosaic, GridConfig(core=64, margin=8))  # 2 x 3 patches of 80 px
        maps = predict_mosaic_maps(model, mosaic, grid, torch.device("cpu"), progress=False)
        a, b = grid.patch(0, 0), grid.patch(0, 1)
        ra, rb = mosaic.read(a.expanded), mosaic.read(b.expanded)  # both reach beyond the mosaic: filled as predicted
        pa = predict_probabilities(model, fill_nodata(ra.data, ra.valid), torch.device("cpu"))
        pb = predict_probabilities(model, fill_nodata(rb.data, rb.valid), torch.device("cpu"))
    assert maps.shape == (2, 96, 160) and (maps >= 0).all() and (maps <= 1).all()
    # Column 60, row 20 lies in the expanded windows of (0,0) [-8, 72) and (0,1) [56, 136) only.
    assert len(grid.patches_covering(60, 20)) == 2
    expected = (pa[:, 20 + 8, 60 + 8] + pb[:, 20 + 8, 60 - 56]) / 2
    assert np.allclose(maps[:, 20, 60], expected, atol=1e-6)
    # Column 30, row 20 is covered by patch (0,0) alone.
    assert np.allclose(maps[:, 20, 30], pa[:, 28, 38], atol=1e-6)


@settings(max_examples=20, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.integers(0, 2**31))
def test_afanet_input_is_bands_over_255_then_maps_bit_for_bit(h, w, seed):
    """The in-place AfANet input equals the concatenation it replaces, to the last bit."""
    from csboundary.models.maps import bands_and_maps, unit_bands

    rng = np.random.default_rng(seed)
    bands = rng.integers(0, 256, (4, h, w), dtype=np.uint8)
    maps = rng.random((2, h, w), dtype=np.float32)
    expected = torch.cat([torch.from_numpy(unit_bands(bands)), torch.from_numpy(maps)]).numpy()
    assert np.array_equal(bands_and_maps(bands, maps), expected)


def test_afanet_input_refuses_other_than_8_bit_bands():
    from csboundary.errors import InputError
    from csboundary.models.maps import bands_and_maps

    with pytest.raises(InputError, match="8-bit"):
        bands_and_maps(np.zeros((4, 8, 8), np.uint16), np.zeros((2, 8, 8), np.float32))
