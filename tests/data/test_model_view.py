"""Ground units (metres from any CRS) and the model's view of imagery (resampled, stretched)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.geotiff import write_geotiff
from csboundary.data.model_view import BandStretch, ResampledMosaic, model_view
from csboundary.data.raster import Mosaic
from csboundary.data.units import ground_units
from csboundary.data.windows import PixelWindow
from csboundary.errors import InputError, InputWarning


def test_metric_and_feet_units_by_hand():
    assert ground_units("EPSG:32618").metres_per_unit == (1.0, 1.0)
    feet = ground_units("EPSG:2263")
    assert feet.metres_per_unit[0] == pytest.approx(1200 / 3937, rel=1e-9)  # the US survey foot
    assert feet.line_length_m(np.array([[0, 0], [3, 4]])) == pytest.approx(5 * 1200 / 3937)


def test_degrees_are_measured_on_the_ellipsoid():
    wgs = ground_units("EPSG:4326", (0.0, 0.0))
    assert wgs.geographic
    assert wgs.metres_per_unit[0] == pytest.approx(111319.49, rel=1e-5)  # a degree of longitude on the equator
    assert wgs.line_length_m(np.array([[0.0, 0.0], [1.0, 0.0]])) == pytest.approx(111319.49, rel=1e-5)
    north = ground_units("EPSG:4326", (0.0, 60.0))
    assert north.metres_per_unit[0] == pytest.approx(wgs.metres_per_unit[0] * math.cos(math.radians(60)), rel=3e-3)


def test_no_crs_needs_a_pixel_size():
    assert ground_units(None) is None
    assert ground_units(None, pixel_metres=0.2).line_length_m(np.array([[0, 0], [10, 0]])) == pytest.approx(2.0)


def test_stretch_maps_low_to_0_and_high_to_255_and_clips():
    stretch = BandStretch((100.0,) * 4, (300.0,) * 4)
    data = np.array([50, 100, 200, 300, 9000], np.float32).reshape(1, 1, 5).repeat(4, axis=0)
    assert stretch.apply(data)[0, 0].tolist() == [0, 0, 128, 255, 255]


def ramp_tile(path, gsd: float, size: int = 120):
    cols = np.arange(size, dtype=np.float32)
    world_x = (cols + 0.5) * gsd  # value = metres east of the origin, at the pixel centre
    band = np.tile(np.clip(world_x * 10, 0, 255), (size, 1)).astype(np.uint8)
    return write_geotiff(path, np.stack([band] * 4), Affine(gsd, 0, 500000, 0, -gsd, 4400000), "EPSG:32618")


@given(st.floats(0.08, 0.45))
@settings(max_examples=8, deadline=None)
def test_resampled_pixels_show_what_lies_at_their_place(tmp_path_factory, gsd):
    path = ramp_tile(tmp_path_factory.mktemp("r") / "ramp.tif", gsd)
    with Mosaic.open(path) as source:
        view = ResampledMosaic(source, 0.152, 0.152, None)
        read = view.read(PixelWindow(5, 5, 40, 10))
    centres = (np.arange(5, 45) + 0.5) * 0.152  # metres east of each view pixel's centre
    inside = centres < (120 * gsd - 2 * gsd) * 0.9
    expected = np.clip(centres * 10, 0, 255)
    assert (
        np.abs(read.data[0, 5, inside].astype(float) - expected[inside]).max() <= 2.5 + 10 * gsd
    )  # one source pixel's blur


def test_model_view_leaves_model_sized_8_bit_imagery_alone_and_refuses_unknown_scale(tmp_path):
    path = ramp_tile(tmp_path / "at_model.tif", 0.152)
    with Mosaic.open(path) as mosaic:
        assert model_view(mosaic).mosaic is mosaic
    plain = write_geotiff(tmp_path / "plain.tif", np.zeros((4, 30, 30), np.uint8), Affine.identity(), None)
    with pytest.warns(InputWarning):
        mosaic = Mosaic.open(plain)
    with pytest.raises(InputError, match="--gsd"):
        model_view(mosaic)
    assert model_view(mosaic, gsd=0.152).mosaic.width == 30
