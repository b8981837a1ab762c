"""The dense-urban style (NYC at 0.152 m) and its photo-look knobs: reproducible, its ground truth
is the roadway's outline and nothing else (not cars, roofs, lots or fields), and every older style
renders byte for byte as before the knobs existed."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import shapely

from csboundary.data.synth.camera import CameraLook, apply_look
from csboundary.data.synth.city import draw_look, plan_city
from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.render import Canvas, TileFrame, draw_detailed_car
from csboundary.data.synth.scene import WHITE_PAINT, WINDOW, Car, centred_rect
from csboundary.data.synth.styles import STYLES, style_config

PHOTO_KNOBS = (
    "road_wear_per_km",
    "car_detail",
    "flat_roof_detail",
    "relief_lean",
    "tree_pits",
    "court_share",
    "lot_stalls",
    "photo_texture",
    "photo_blur",
    "jpeg_quality",
    "house_depth",
    "bare_tree_share",
    "bus_lane_share",
)

# md5 of the ground-truth WKB of tile (0, 0) of each older style's seed-7 test city at 1000 px,
# recorded before the dense style's knobs were added (2026-12-04). The ground truth is exact
# geometry, so it is pinned exactly; the rendered image is not (see IMAGE_BLOCK below).
OLDER_STYLE_TRUTH_MD5 = {
    "classic": "e72e995384fab5c1f63c843d134e3d62",
    "grid": "848d582eea9a6342eed487126e816478",
    "downtown": "e6fae73763e1c0e84ffaef04f7706171",
    "suburb": "5083a2081b925fd2978679480a4080bf",
    "rural": "2826015734dcad4cb32185ed54b98d6d",
    "residential": "d00f3304ffcac552aecee41c77a79e88",
    "leafy": "d00f3304ffcac552aecee41c77a79e88",
    "highway": "135ff2f4719f4612eb90016e419fb7fb",
    "irregular": "28fd6a75b8f4e17afa56491e96035feb",
}
# The same tiles' images as the means of 20x20-px blocks, in hundredths of a grey level
# (reference/older-styles-blocks.npz, written by ``python tests/data/test_synth_dense.py`` from
# renders whose md5 matched the images recorded on 2026-12-04). The renderer's floating point
# (OpenBLAS picks its kernels by CPU) differs in the last bits between CPUs: with OpenBLAS's Haswell
# or Zen kernels instead of SkylakeX, the residential tile changes 0.03 % of its pixel values by
# 1-7 grey levels, which moves 0.3 % of its block means, by at most 0.58 of a grey level. So a
# render is "as before" when at most 2 % of block means move by more than 0.02 (their rounding)
# and none by more than 3 grey levels: a changed random draw moves most blocks, and one added or
# moved car, tree or marking moves its block by far more than 3 levels.
IMAGE_BLOCK = 20
REFERENCE = Path(__file__).parent / "reference" / "older-styles-blocks.npz"
MOVED_SHARE, MOVED_BY, MAX_MOVE = 0.02, 0.02, 3.0


def block_means(image: np.ndarray) -> np.ndarray:
    """(bands, rows / IMAGE_BLOCK, cols / IMAGE_BLOCK) means of an image's square blocks."""
    bands, rows, cols = image.shape
    blocks = image.reshape(bands, rows // IMAGE_BLOCK, IMAGE_BLOCK, cols // IMAGE_BLOCK, IMAGE_BLOCK)
    return blocks.astype(float).mean(axis=(2, 4))


def render_older_style(style: str) -> tuple[np.ndarray, str]:
    """Tile (0, 0) of the style's seed-7 test city at 1000 px, and its ground truth's md5."""
    city = plan_city(style_config(style, tile_size=1000), "test", 7, (1, 1))
    truth = hashlib.md5(b"".join(g.wkb for g in city.ground_truth().geometry)).hexdigest()
    return city.render(0, 0), truth


def small(style: str = "dense", **overrides) -> SynthConfig:
    return style_config(style, tile_size=800, gsd=0.5, **overrides)  # 400 m square


def test_every_style_is_pinned_here_or_is_dense():
    assert set(STYLES) == set(OLDER_STYLE_TRUTH_MD5) | {"dense"}
    with np.load(REFERENCE) as reference:
        assert set(reference.files) == set(OLDER_STYLE_TRUTH_MD5)


def moved_blocks(image: np.ndarray, reference_hundredths: np.ndarray) -> tuple[float, float]:
    """(share of block means moved by more than MOVED_BY, largest move) against the reference."""
    move = np.abs(block_means(image) - reference_hundredths / 100.0)
    return float((move > MOVED_BY).mean()), float(move.max())


@pytest.mark.parametrize("style", sorted(OLDER_STYLE_TRUTH_MD5))
def test_older_styles_render_as_before_the_dense_knobs(style):
    image, truth = render_older_style(style)
    assert truth == OLDER_STYLE_TRUTH_MD5[style]
    with np.load(REFERENCE) as reference:
        share, largest = moved_blocks(image, reference[style])
    assert share <= MOVED_SHARE and largest <= MAX_MOVE, (share, largest)


def test_the_render_check_tells_a_moved_car_from_another_cpus_rounding():
    image, _ = render_older_style("residential")
    with np.load(REFERENCE) as reference:
        blocks = reference["residential"]
    # another CPU's rounding: 0.05 % of pixel values one or two grey levels off, anywhere
    rng = np.random.default_rng(0)
    noisy = image.astype(int)
    flat = noisy.reshape(-1)
    picked = rng.choice(flat.size, flat.size // 2000, replace=False)
    flat[picked] = np.clip(flat[picked] + rng.choice([-2, -1, 1, 2], len(picked)), 0, 255)
    share, largest = moved_blocks(noisy.astype(np.uint8), blocks)
    assert largest <= MAX_MOVE and share <= MOVED_SHARE
    # a car-sized dark rectangle (2 x 4.5 m at 0.152 m) where there was none
    car = image.copy()
    car[:3, 400:413, 300:330] = 20
    assert moved_blocks(car, blocks)[1] > MAX_MOVE


def test_older_styles_render_as_before_with_another_blas_kernel():
    # OpenBLAS's Haswell kernels stand in for another CPU: the residential tile renders 0.03 % of
    # its pixel values differently with them (above), and the check must still pass
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import test_synth_dense as t; "
        "t.test_older_styles_render_as_before_the_dense_knobs('residential')"
    )
    env = dict(os.environ, OPENBLAS_CORETYPE="Haswell")
    result = subprocess.run(
        [sys.executable, "-c", code, str(Path(__file__).parent)], env=env, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("style", sorted(OLDER_STYLE_TRUTH_MD5))
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
    assert all(b.parapet is not None or b.facets for b in scene.buildings[:3]) or any(
        b.parapet for b in scene.buildings
    )
    assert any(len(b.roof_items) > 0 for b in scene.buildings)
    assert scene.lean != (0.0, 0.0) and scene.texture > 0
    assert all(car.detail for car in scene.cars)
    parked = [c for c in scene.cars if scene.network.roadway.contains(c.body)]
    assert len(parked) / (sum(s.centreline.length for s in streets) / 1000) > 100  # cars per km of street


def test_dense_photo_knobs_change_the_pixels_but_not_the_ground_truth():
    plain = {
        "road_wear_per_km": 0.0,
        "car_detail": False,
        "flat_roof_detail": 0.0,
        "relief_lean": (0.0, 0.0),
        "photo_texture": 0.0,
        "photo_blur": (0.0, 0.0),
        "jpeg_quality": (0, 0),
    }
    a, b = plan_city(small(), "train", 4, (1, 1)), plan_city(small(**plain), "train", 4, (1, 1))
    assert [g.wkb for g in a.ground_truth().geometry] == [g.wkb for g in b.ground_truth().geometry]
    assert not np.array_equal(a.render(0, 0), b.render(0, 0))
    assert draw_look(b.config, "train", 4).jpeg == 0


def test_a_detailed_white_car_has_dark_windows_and_a_lit_roof():
    frame = TileFrame(0.0, 20.0, 200, 0.1)
    canvas = Canvas(frame)
    body = centred_rect(np.array([10.0, 10.0]), np.array([1.0, 0.0]), 4.6, 1.9)
    car = Car(body, (200, 200, 200, 180), body, detail=True)  # a light car facing east
    draw_detailed_car(canvas, car)
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


if __name__ == "__main__":  # rewrite the reference from this machine's renders
    np.savez_compressed(
        REFERENCE,
        **{
            style: np.round(block_means(render_older_style(style)[0]) * 100).astype(np.uint16)
            for style in sorted(OLDER_STYLE_TRUTH_MD5)
        },
    )
