"""Extremes over a disc (graph/disc_filter.py) and the surface gate built on them: the same as
taking every pixel of the disc, at any radius the gate allows."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.graph.disc_filter import OPENCV_UP_TO_PX, disc_kernel, disc_max, disc_min, disc_plan
from csboundary.graph.surface_gate import SurfaceGateConfig, gated_maps, patch_surface_change, surface_change
from csboundary.graph.vertex_extraction import extract_vertices


def every_offset(image: np.ndarray, radius: int, pick) -> np.ndarray:
    """The straightforward reference: ``pick`` over every pixel of the disc, border replicated."""
    h, w = image.shape
    padded = np.pad(image, radius, mode="edge")
    ys, xs = np.nonzero(disc_kernel(radius))
    out = padded[ys[0] : ys[0] + h, xs[0] : xs[0] + w].copy()
    for y, x in zip(ys.tolist(), xs.tolist()):
        pick(out, padded[y : y + h, x : x + w], out=out)
    return out


def hand_made(h: int = 40, w: int = 56) -> np.ndarray:
    """Maps (keypoint, boundary, surface) of a street along the top, a lot at the bottom right,
    and a roof's outline that no roadway explains."""
    surface = np.zeros((h, w), np.float32)
    surface[4:14] = 0.95
    surface[28:36, 40:52] = 0.7
    surface[14, :] = 0.4  # a soft curb
    keypoint = np.zeros((h, w), np.float32)
    boundary = np.zeros((h, w), np.float32)
    boundary[[4, 14]] = 0.9  # both curbs
    boundary[22:26, 8] = boundary[22, 8:20] = 0.8  # the roof
    for y, x in ((14, 6), (14, 50), (22, 8), (22, 19), (4, 30)):
        keypoint[y - 1 : y + 2, x - 1 : x + 2] = [[0.3, 0.6, 0.3], [0.6, 0.95, 0.6], [0.3, 0.6, 0.3]]
    return np.stack([keypoint, boundary, surface])


@pytest.mark.parametrize("radius", [OPENCV_UP_TO_PX + 1, 23, 64, 200])
def test_the_extremes_are_those_of_every_disc_pixel(radius):
    image = np.random.default_rng(radius).random((19, 33)).astype(np.float32)
    assert np.array_equal(disc_max(image, radius), every_offset(image, radius, np.maximum))
    assert np.array_equal(disc_min(image, radius), every_offset(image, radius, np.minimum))


def test_every_radius_the_gate_allows_is_a_sum_of_steps_inside_the_disc_taken_in_few_passes():
    for radius in range(OPENCV_UP_TO_PX + 1, 201):
        plan = disc_plan(radius)
        assert plan is not None, radius
        doubling = sum(n.bit_length() - 1 + (n & (n - 1) != 0) for _, n in plan.steps)
        passes = doubling + sum(1 + (n & (n - 1) != 0) for _, _, n in plan.rest)
        assert passes < 200, radius  # OpenCV's kernel: one per disc pixel (126,000 at 200 px)


@pytest.mark.parametrize("radius", [30, 150])
def test_a_large_gate_decides_as_the_gate_of_every_disc_pixel(radius):
    maps = hand_made()
    config = SurfaceGateConfig(radius_px=radius, min_piece_px=0, full_change=0.6)
    surface = maps[2]
    spread = every_offset(surface, radius, np.maximum) - every_offset(surface, radius, np.minimum)
    reference = np.clip(spread / np.float32(config.full_change), 0, 1)
    assert np.array_equal(surface_change(surface, config), reference)
    gated = gated_maps(maps, 2, config)
    expected = maps.copy()
    expected[:2] *= reference
    assert np.array_equal(gated, expected)
    found, wanted = extract_vertices(gated[0]), extract_vertices(expected[0])
    assert np.array_equal(found.vertices, wanted.vertices) and found.n_vertices > 0


def test_a_patch_is_gated_once_for_its_vertices_and_again_for_its_edges():
    maps = hand_made()
    config = SurfaceGateConfig(radius_px=40, min_piece_px=0)
    first = patch_surface_change(maps[2], config)
    assert patch_surface_change(maps[2].copy(), config) is first  # the same surface: kept
    assert not first.flags.writeable
    other = maps[2].copy()
    other[0, 0] = 0.5
    assert patch_surface_change(other, config) is not first
    assert np.array_equal(
        patch_surface_change(maps[2], SurfaceGateConfig(radius_px=41, min_piece_px=0)),
        surface_change(maps[2], SurfaceGateConfig(radius_px=41, min_piece_px=0)),
    )
