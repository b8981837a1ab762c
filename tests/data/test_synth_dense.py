"""The dense-urban style (NYC at 0.152 m) and its photo-look knobs: reproducible, its ground truth
is the roadway's outline and nothing else (not cars, roofs, lots or fields), and every older style
renders byte for byte as before the knobs existed."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import shapely

from csboundary.data.synth.city import draw_look, plan_city
from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.render import CameraLook, TileFrame, _Canvas, _draw_detailed_car, apply_look
from csboundary.data.synth.scene import WHITE_PAINT, WINDOW, Car, _centred_rect
from csboundary.data.synth.styles import STYLES, style_config

PHOTO_KNOBS = ("road_wear_per_km", "car_detail", "flat_roof_detail", "relief_lean", "tree_pits", "court_share",
               "lot_stalls", "photo_texture", "photo_blur", "jpeg_quality", "house_depth", "bare_tree_share",
               "bus_lane_share")

# md5 of (image bytes, ground-truth WKB) of tile (0, 0) of each older style's seed-7 test city at
# 1000 px, recorded before the dense style's knobs were added (2026-12-04)
OLDER_STYLE_MD5 = {
    "classic": ("bc35920cfce696a8d118c16b5f465e12", "e72e995384fab5c1f63c843d134e3d62"),
    "grid": ("fc0052f0094b1b18923ba5ef29e83098", "848d582eea9a6342eed487126e816478"),
    "downtown": ("54eec05ba33a9b1a73f4c0998a232392", "e6fae73763e1c0e84ffaef04f7706171"),
    "suburb": ("732d5be7551aa02557b875a6691d0aeb", "5083a2081b925fd2978679480a4080bf"),
    "rural": ("28c451473f26b3afa8726a9c8eaf3d5b", "2826015734dcad4cb32185ed54b98d6d"),
    "residential": ("ea1ec151a8ebcd33ac5f46cefb1fac10", "d00f3304ffcac552aecee41c77a79e88"),
    "leafy": ("a85b3dcbea8dc6bf19dc9d0c423924b3", "d00f3304ffcac552aecee41c77a79e88"),
    "highway": ("e658c23f3de171c0f8b9a696f8c02085", "135ff2f4719f4612eb90016e419fb7fb"),
    "irregular": ("e914763587ecc57618c085bf1981a7ac", "28fd6a75b8f4e17afa56491e96035feb"),
}


def small(style: str = "dense", **overrides) -> SynthConfig:
    return style_config(style, tile_size=800, gsd=0.5, **overrides)  # 400 m square


def test_every_style_is_pinned_here_or_is_dense():
    assert set(STYLES) == set(OLDER_STYLE_MD5) | {"dense"}


@pytest.mark.parametrize("style", sorted(OLDER_STYLE_MD5))
def test_older_styles_render_byte_for_byte_as_before_the_dense_knobs(style):
    city = plan_city(style_config(style, tile_size=1000), "test", 7, (1, 1))
    image = hashlib.md5(city.render(0, 0).tobytes()).hexdigest()
    truth = hashlib.md5(b"".join(g.wkb for g in city.ground_truth().geometry)).hexdigest()
    assert (image, truth) == OLDER_STYLE_MD5[style]


@pytest.mark.parametrize("style", sorted(OLDER_STYLE_MD5))
def test_photo_knobs_are_off_in_every_older_style(style):
    config, default = style_config(style), SynthConfig()
    assert all(getattr(config, knob) == getattr(default, knob) for knob in PHOTO_KNOBS)
    assert config.roof_palette != "tar"


def test_dense_city_is_reproduced_from_its_seed():
    a, b = plan_city(small(), "train", 9, (1, 1)), plan_city(small(), "train", 9, (1, 1))
    assert [g.wkb for g in a.ground_truth().geometry] == [g.wkb for g in b.ground_truth().geometry]
    assert a.look == b.look and a.look.jpeg >= 60 and a.look.blur > 0
    assert np.array_equal(a.render(0, 0), b.render(0, 0))
    c = plan_city(small(), "train", 10, (1, 1))
    assert not np.array_equal(a.render(0, 0), c.render(0, 0))


@pytest.fixture(scope="module")
def dense_city():
    # more parks and lots than the style's share, so the 400 m city surely has fields and stalls
    return plan_city(small(park_share=0.3, lot_share=0.3), "train", 4, (1, 1))


def test_dense_ground_truth_is_the_roadway_outline(dense_city):
    network = dense_city.scene.network
    outline = shapely.union_all([p.boundary for p in getattr(network.roadway, "geoms", [network.roadway])])
    assert len(network.boundaries) > 0
    for line, _ in network.boundaries:
        assert line.hausdorff_distance(line.intersection(outline.buffer(1e-6))) < 1e-6
        assert outline.buffer(1e-6).contains(line)


def test_dense_ground_truth_is_not_along_cars_roofs_lots_or_fields(dense_city):
    scene = dense_city.scene
    truth = shapely.union_all([line for line, _ in scene.network.boundaries])
    field_paint = [p.polygon for p in scene.ground if p.colour == WHITE_PAINT]  # court lines and parking stalls
    assert len(field_paint) > 20
    assert min(truth.distance(p) for p in field_paint if not p.is_empty) > 1.0
    roofs = [b.footprint for b in scene.buildings]
    assert len(roofs) > 20 and min(truth.distance(r) for r in roofs) > 2.5  # a 3-6 m sidewalk in between
    for car in scene.cars:  # parked cars stand in front of the curb, never across it
        assert truth.intersection(car.body.buffer(-0.05)).is_empty


def test_dense_style_has_its_street_proportions_and_full_curbs(dense_city):
    scene = dense_city.scene
    streets = scene.network.streets
    assert all(10.0 <= s.width <= 30.0 or s.kind == "boulevard" for s in streets)
    assert all(b.parapet is not None or b.facets for b in scene.buildings[:3]) or any(b.parapet for b in scene.buildings)
    assert any(len(b.roof_items) > 0 for b in scene.buildings)
    assert scene.lean != (0.0, 0.0) and scene.texture > 0
    assert all(car.detail for car in scene.cars)
    parked = [c for c in scene.cars if scene.network.roadway.contains(c.body)]
    assert len(parked) / (sum(s.centreline.length for s in streets) / 1000) > 100  # cars per km of street


def test_dense_photo_knobs_change_the_pixels_but_not_the_ground_truth():
    plain = {"road_wear_per_km": 0.0, "car_detail": False, "flat_roof_detail": 0.0, "relief_lean": (0.0, 0.0),
             "photo_texture": 0.0, "photo_blur": (0.0, 0.0), "jpeg_quality": (0, 0)}
    a, b = plan_city(small(), "train", 4, (1, 1)), plan_city(small(**plain), "train", 4, (1, 1))
    assert [g.wkb for g in a.ground_truth().geometry] == [g.wkb for g in b.ground_truth().geometry]
    assert not np.array_equal(a.render(0, 0), b.render(0, 0))
    assert draw_look(b.config, "train", 4).jpeg == 0


def test_a_detailed_white_car_has_dark_windows_and_a_lit_roof():
    frame = TileFrame(0.0, 20.0, 200, 0.1)
    canvas = _Canvas(frame)
    body = _centred_rect(np.array([10.0, 10.0]), np.array([1.0, 0.0]), 4.6, 1.9)
    car = Car(body, (200, 200, 200, 180), body, detail=True)  # a light car facing east
    _draw_detailed_car(canvas, car)
    row = canvas.image[100, :, 0].astype(int)  # along the car's axis through its centre
    length = car.body.bounds[2] - car.body.bounds[0]
    rear = 10.0 - length / 2

    def at(fraction):
        return row[int((rear + fraction * length) / 0.1)]

    assert at(0.2) == WINDOW[0] and at(0.64) == WINDOW[0]  # rear window, windshield
    assert at(0.42) > at(0.05) > WINDOW[0] + 50  # a lit roof over the body colour


def test_blur_and_jpeg_change_a_noisy_image_but_keep_its_mean():
    rng = np.random.default_rng(1)
    image = rng.integers(60, 200, (4, 64, 64), dtype=np.uint8)
    out = apply_look(image, CameraLook(blur=0.8, jpeg=70))
    assert out.shape == image.shape and out.dtype == np.uint8
    assert not np.array_equal(out, image)
    assert abs(float(out.mean()) - float(image.mean())) < 2.0
    assert out.std() < image.std()  # the blur smooths the noise
    assert CameraLook(jpeg=70).is_identity is False and CameraLook().is_identity
