"""Training augmentation: geometry moves image and labels together, appearance stays in range."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.models.augmentation import AugmentConfig, draw_geometry, photometric, source_side, warp


def test_identity_warp_returns_the_array():
    a = np.random.default_rng(0).random((2, 32, 32)).astype(np.float32)
    assert np.allclose(warp(a, 0.0, 1.0, 32), a, atol=1e-6)


def test_quarter_turn_is_a_rot90():
    a = np.random.default_rng(1).random((31, 31)).astype(np.float32)
    # cv2 turns counter-clockwise for a positive angle in image coordinates (y down), as np.rot90
    assert np.allclose(warp(a, math.pi / 2, 1.0, 31), np.rot90(a), atol=1e-5)


def test_zoom_doubles_distances_from_the_centre():
    a = np.zeros((41, 41), np.float32)
    a[20, 25] = 1  # 5 px right of the centre
    out = warp(a, 0.0, 2.0, 41, nearest=True)
    assert out[20, 30] == 1


@settings(max_examples=60, deadline=None)
@given(st.floats(0, 2 * math.pi), st.floats(0.7, 1.4), st.integers(16, 200))
def test_source_window_covers_the_rotated_crop(angle, scale, crop):
    side = source_side(crop, angle, scale)
    covered = warp(np.ones((side, side), np.uint8), angle, scale, crop, nearest=True)
    assert covered.all()


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_photometric_keeps_shape_range_and_dtype(seed):
    rng = np.random.default_rng(seed)
    image = rng.random((4, 40, 40)).astype(np.float32)
    out = photometric(rng, image, AugmentConfig())
    assert out.shape == image.shape and out.dtype == np.float32
    assert out.min() >= 0 and out.max() <= 1


def test_nir_replaced_by_green_as_rgb_input_is_read():
    rng = np.random.default_rng(0)
    image = rng.random((4, 16, 16)).astype(np.float32)
    out = photometric(rng, image, AugmentConfig(nir_as_green_p=1.0))
    assert np.array_equal(out[3], out[1])
    out = photometric(rng, image, AugmentConfig(nir_as_green_p=0.0, jpeg_p=0, noise_p=0, blur_p=0))
    assert not np.array_equal(out[3], out[1])


def test_disabled_augmentation_changes_nothing_and_draws_nothing():
    rng = np.random.default_rng(0)
    image = rng.random((4, 8, 8)).astype(np.float32)
    state = rng.bit_generator.state
    off = AugmentConfig(enabled=False)
    assert photometric(rng, image, off) is image
    assert draw_geometry(rng, off) == (0.0, 1.0)
    assert rng.bit_generator.state == state


def test_same_seed_same_sample():
    image = np.random.default_rng(5).random((4, 24, 24)).astype(np.float32)
    a = photometric(np.random.default_rng(9), image, AugmentConfig())
    b = photometric(np.random.default_rng(9), image, AugmentConfig())
    assert np.array_equal(a, b)


def test_scale_draws_stay_in_range():
    rng = np.random.default_rng(0)
    scales = [draw_geometry(rng, AugmentConfig())[1] for _ in range(500)]
    assert 0.7 <= min(scales) and max(scales) <= 1.4
    assert min(scales) < 0.8 and max(scales) > 1.3


def test_misspelt_augmentation_option_is_an_error(tmp_path):
    from csboundary.models.training.config import TrainConfig, model_config_with

    cfg = TrainConfig.from_dict({"augment": {"rotation": True}})
    with pytest.raises(ValueError, match="rotation"):
        model_config_with(AugmentConfig, cfg.augment)
