"""Leafy suburbs: clumped canopy over the yards and lobed crowns lit from the sun's side. They
change pixels, never the ground truth, and stay off in every other style."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import box

from csboundary.data.synth.city import plan_city
from csboundary.data.synth.render import Canvas, TileFrame, draw_lobed_crown
from csboundary.data.synth.scene import Scene, Tree, add_canopy
from csboundary.data.synth.styles import STYLES, style_config


def small(style: str, **overrides):
    return style_config(style, tile_size=800, gsd=0.5, **overrides)  # 400 m square


@pytest.mark.parametrize("style", sorted(set(STYLES) - {"leafy"}))
def test_canopy_knobs_are_off_in_every_other_style(style):
    config = style_config(style)
    assert config.yard_canopy == (0.0, 0.0) and config.crown_lobes == 5


def test_canopy_changes_the_pixels_but_not_the_ground_truth():
    leafy = plan_city(small("leafy"), "train", 4, (1, 1))
    plain = plan_city(small("leafy", yard_canopy=(0.0, 0.0), crown_lobes=5), "train", 4, (1, 1))
    assert [g.wkb for g in leafy.ground_truth().geometry] == [g.wkb for g in plain.ground_truth().geometry]
    assert len(leafy.scene.trees) > len(plain.scene.trees)
    assert not np.array_equal(leafy.render(0, 0), plain.render(0, 0))


@settings(max_examples=30, deadline=None)
@given(cover=st.floats(0.05, 0.6), side=st.floats(30.0, 120.0), seed=st.integers(0, 2**31))
def test_canopy_crowns_add_up_to_the_cover_asked_for(cover, side, seed):
    """Clumps are added until the crowns' summed area reaches ``cover``: it overshoots by at most
    one clump (8 crowns of 7 m), and every clump is centred inside the yard."""
    yard = box(0, 0, side, side)
    scene = Scene(network=None)  # type: ignore[arg-type]
    add_canopy(np.random.default_rng(seed), scene, yard, cover, lobes=12)
    area = sum(math.pi * t.radius**2 for t in scene.trees)
    assert cover * yard.area <= area < cover * yard.area + 8 * math.pi * 7.0**2
    assert all(3.0 <= t.radius <= 7.0 and t.lobes == 12 for t in scene.trees)


def test_a_lobed_crown_is_brighter_on_the_sun_side():
    """Shadows fall to +x (sun offset (0.5, 0)), so the sun is in the west: the crown's west half
    is lit, its east half shaded; the ground around it is untouched."""
    frame = TileFrame(x0=0.0, y1=40.0, size=200, gsd=0.2)
    canvas = Canvas(frame, road=(100, 100, 100, 100))
    tree = Tree(20.0, 20.0, 6.0, (60, 90, 45, 190), shape_seed=7, lobes=40)
    draw_lobed_crown(canvas, tree, np.random.default_rng(tree.shape_seed), sun=(0.5, 0.0))
    green = canvas.image[..., 1].astype(float)
    west, east = green[80:120, 75:100].mean(), green[80:120, 100:125].mean()
    assert west > east + 5  # 0.35 x offset of brightness: about 10 % on a crown of many lobes
    assert (canvas.image[:5, :5] == 100).all()
