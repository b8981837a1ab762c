"""Residential yards: pitched roofs, driveways to the house, fences, lawns, pools. They change
pixels, never the ground truth, and stay off in every style that predates them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon
from shapely.ops import unary_union

from csboundary.data.synth.city import plan_city
from csboundary.data.synth.scene import DRIVEWAYS, roof_facets
from csboundary.data.synth.styles import STYLES, style_config

YARD_KNOBS = (
    "bare_block_share",
    "pitched_roof_share",
    "house_driveway_share",
    "lot_fence_share",
    "lawn_patch_share",
    "pool_share",
)


def small(style: str, **overrides):
    return style_config(style, tile_size=800, gsd=0.5, **overrides)  # 400 m square


def test_gable_roof_over_a_10_by_6_rectangle_is_two_halves_split_by_the_long_ridge():
    facets, ridge = roof_facets(
        np.zeros(2), np.array([1.0, 0.0]), np.array([0.0, 1.0]), 10.0, 6.0, hip=False, sun=(0.0, -1.0)
    )
    assert [round(f.area, 9) for f, _ in facets] == [30.0, 30.0]
    assert ridge is not None and ridge.centroid.coords[0] == pytest.approx((5.0, 3.0))
    assert ridge.bounds == pytest.approx((0.0, 2.88, 10.0, 3.12))  # along the long side, 0.24 m wide
    # Shadows fall to -y, so the sun is at +y: the +y facet is lit (1.3), the -y one shaded (0.7).
    by_side = {round(f.centroid.y, 6): b for f, b in facets}
    assert by_side == {1.5: pytest.approx(0.7), 4.5: pytest.approx(1.3)}


def test_hip_roof_on_a_square_is_four_triangles_meeting_at_the_centre_without_a_ridge():
    facets, ridge = roof_facets(
        np.zeros(2), np.array([1.0, 0.0]), np.array([0.0, 1.0]), 8.0, 8.0, hip=True, sun=(1.0, 0.0)
    )
    assert len(facets) == 4 and ridge is None
    assert all(f.area == pytest.approx(16.0) for f, _ in facets)
    assert sorted(round(b, 9) for _, b in facets) == [0.7, 1.0, 1.0, 1.3]  # the -x facet faces the sun


@given(
    st.floats(2.0, 30.0), st.floats(2.0, 30.0), st.floats(0.0, 2 * math.pi), st.booleans(), st.floats(0.0, 2 * math.pi)
)
@settings(max_examples=60, deadline=None)
def test_roof_facets_tile_the_footprint_and_the_ridge_runs_along_its_longer_side(length, width, angle, hip, sun_angle):
    along = np.array([math.cos(angle), math.sin(angle)])
    across = np.array([-along[1], along[0]])
    origin = np.array([3.0, -7.0])
    footprint = Polygon(
        [origin, origin + along * length, origin + along * length + across * width, origin + across * width]
    )
    facets, ridge = roof_facets(origin, along, across, length, width, hip, (math.cos(sun_angle), math.sin(sun_angle)))
    assert len(facets) == (4 if hip else 2)
    assert sum(f.area for f, _ in facets) == pytest.approx(footprint.area, rel=1e-9)
    assert unary_union([f for f, _ in facets]).symmetric_difference(footprint).area < 1e-6 * footprint.area
    assert all(0.7 - 1e-9 <= b <= 1.3 + 1e-9 for _, b in facets)
    if ridge is not None:
        ridge_length = max(length, width) - (min(length, width) if hip else 0.0)
        assert ridge.area == pytest.approx(0.24 * ridge_length, rel=1e-6)
        assert footprint.buffer(1e-9).contains(ridge)


@pytest.mark.parametrize(
    "style", sorted(set(STYLES) - {"residential", "leafy", "highway"})
)  # the styles built before the knobs
def test_yard_knobs_are_off_in_every_style_that_predates_them(style):
    config = style_config(style)
    assert all(getattr(config, knob) == 0.0 for knob in YARD_KNOBS)


def test_yards_change_the_pixels_but_not_the_ground_truth():
    with_yards = plan_city(small("residential"), "train", 4, (1, 1))
    bare = plan_city(small("residential", **{k: 0.0 for k in YARD_KNOBS}), "train", 4, (1, 1))
    assert [g.wkb for g in with_yards.ground_truth().geometry] == [g.wkb for g in bare.ground_truth().geometry]
    assert not np.array_equal(with_yards.render(0, 0), bare.render(0, 0))


def test_residential_houses_have_pitched_roofs_and_driveways_that_stop_at_the_curb():
    scene = plan_city(small("residential"), "train", 4, (1, 1)).scene
    houses = scene.buildings
    pitched = [b for b in houses if b.facets]
    assert len(pitched) > 0.6 * len(houses)
    for b in pitched:  # the facets cover the footprint
        assert sum(f.area for f, _ in b.facets) == pytest.approx(b.footprint.area, rel=1e-6)
    driveway_colours = {c[:3] for c in DRIVEWAYS}
    roadway = scene.network.roadway
    paved = [
        p.polygon
        for p in scene.ground
        if p.roughness == 5
        and p.polygon.area > 15
        and any(np.abs(np.subtract(p.colour[:3], c)).max() <= 30 for c in driveway_colours)
    ]
    assert len(paved) > 10
    assert max(roadway.intersection(p).area for p in paved) < 0.05  # clipped to the block: never on the road
