"""City styles: each style's defining geometry, reproducibility, the camera look, style mixes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point

from csboundary.data.synth.camera import HAZE_VEIL, CameraLook, apply_look, resample
from csboundary.data.synth.city import draw_look, plan_city
from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.scene import CONCRETE, GRAVEL, SOIL
from csboundary.data.synth.streets import rng_share
from csboundary.data.synth.styles import DEFAULT_MIX, MAJOR_STYLES, STYLES, draw_style, style_config
from csboundary.models.training.config import TrainConfig, training_cities
from csboundary.models.training.data import CitySpec, WorldsConfig
from helpers import run_cli


def small(style: str, **overrides) -> SynthConfig:
    return style_config(style, tile_size=800, gsd=0.5, **overrides)  # 400 m square


@pytest.mark.parametrize("style", sorted(STYLES))
def test_every_style_builds_a_city_with_boundaries_inside_it(style):
    city = plan_city(small(style), "train", 4, (1, 1))
    gt = city.ground_truth()
    assert len(gt) > 0
    x0, y0 = city.config.origin_x, city.config.origin_y
    minx, miny, maxx, maxy = gt.total_bounds
    assert minx >= x0 - 1e-6 and miny >= y0 - 1e-6 and maxx <= x0 + 400 + 1e-6 and maxy <= y0 + 400 + 1e-6
    assert city.scene.network.roadway.is_valid


@pytest.mark.parametrize("style", MAJOR_STYLES)
def test_a_style_city_is_reproduced_from_its_seed(style):
    a = plan_city(small(style), "train", 9, (1, 1))
    b = plan_city(small(style), "train", 9, (1, 1))
    assert [g.wkb for g in a.ground_truth().geometry] == [g.wkb for g in b.ground_truth().geometry]
    assert a.look == b.look
    assert np.array_equal(a.render(0, 0), b.render(0, 0))


# NumPy features whose kernels round some functions' last bit differently (AVX-512 machines)
WIDE_SIMD = "X86_V4 AVX512_ICL AVX512_SPR AVX512_SKX"
GROUND_TRUTH_HASH = (
    "import hashlib, sys; from csboundary.data.synth.city import plan_city; from csboundary.data.synth.styles import style_config; "
    "city = plan_city(style_config(sys.argv[1], tile_size=2000), 'test', 7, (2, 2)); "
    "print(hashlib.sha256(b''.join(g.wkb for g in city.ground_truth().geometry)).hexdigest())"
)


def test_a_city_is_the_same_on_cpus_with_and_without_avx512(style="suburb"):
    # the suburb test city (seed 7, 2x2 tiles of 2000 px) was another city on an AVX-512
    # machine: NumPy's power, one bit off, decided whether two streets crossed
    import os
    import subprocess
    import sys

    from numpy._core._multiarray_umath import __cpu_features__

    if not any(__cpu_features__.get(f) for f in WIDE_SIMD.split()):
        pytest.skip("this CPU has none of the features to switch off")
    hashes = []
    for disabled in ("", " ".join(f for f in WIDE_SIMD.split() if __cpu_features__.get(f))):
        env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": disabled}
        done = subprocess.run(
            [sys.executable, "-c", GROUND_TRUTH_HASH, style], env=env, capture_output=True, text=True, check=True
        )
        hashes.append(done.stdout.strip())
    assert hashes[0] == hashes[1]


def test_classic_style_is_the_original_generator():
    assert style_config("classic") == SynthConfig()
    assert draw_look(SynthConfig(), "train", 3) == CameraLook()  # no look: pixels as before styles


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=20, deadline=None)
def test_a_switched_off_knob_draws_no_random_number(seed):
    rng, twin = np.random.default_rng(seed), np.random.default_rng(seed)
    assert rng_share(rng, 0.0) is False
    assert rng.random() == twin.random()  # stream untouched, so the classic city is unchanged


def test_suburb_local_streets_meet_their_parent_at_a_t_junction_and_end_in_bulbs():
    city = plan_city(small("suburb"), "train", 2, (1, 1))
    streets = city.scene.network.streets
    local = [s for s in streets if s.kind == "local"]
    assert len(local) >= 3
    domain_edge = shapely.box(-80, -80, 480, 480).exterior  # streets are clipped 60 + 20 m beyond the city
    for s in local:  # every local street leaves another street (a T-junction) or enters from beyond the margin
        rest = shapely.union_all([o.centreline for o in streets if o is not s])
        start = Point(s.centreline.coords[0])
        assert start.distance(rest) < 1e-6 or start.distance(domain_edge) < 1e-6
    assert any(s.bulb_radius > 0 for s in local)
    assert any(s.bulb_radius == 0 and s.centreline.length > 50 for s in local)


def test_roundabout_ring_is_roadway_around_a_round_island():
    config = small("grid", roundabout_share=1.0)
    network = plan_city(config, "train", 1, (1, 1)).scene.network
    circles = [i for i in network.islands if abs(4 * math.pi * i.area / i.length**2 - 1) < 0.01]
    round_islands = [i for i in circles if shapely.box(0, 0, 400, 400).contains(i.buffer(5.0))]  # inside the city
    assert round_islands
    for island in round_islands:
        ring = island.buffer(3.0).difference(island)  # the lane next to the island
        assert network.roadway.buffer(1e-6).contains(ring)


def test_bulb_islands_sit_inside_cul_de_sac_bulbs():
    config = small("suburb", bulb_island_share=1.0, cul_de_sac_share=1.0, loop_share=0.0)
    network = plan_city(config, "train", 2, (1, 1)).scene.network
    ends = [Point(s.centreline.coords[-1]) for s in network.streets if s.bulb_radius >= 8.0]
    assert ends
    centred = [i for i in network.islands if min(i.centroid.distance(e) for e in ends) < 1e-3]
    assert centred
    for island in centred:
        assert network.roadway.buffer(1e-6).contains(island.buffer(2.0).difference(island))


def test_rural_blocks_meet_the_road_with_a_shoulder_not_a_sidewalk():
    scene = plan_city(small("rural"), "train", 5, (1, 1)).scene
    first_paint = {}
    for item in scene.ground:
        for block in scene.network.blocks:
            if item.polygon.equals(block.polygon) and id(block) not in first_paint:
                first_paint[id(block)] = item.colour
    assert first_paint
    for colour in first_paint.values():
        near = [np.abs(np.subtract(colour[:3], c[:3])).max() for c in (GRAVEL, SOIL, CONCRETE)]
        assert min(near[:2]) < near[2]  # gravel or soil, not concrete


def test_look_identity_returns_the_image_unchanged():
    image = np.random.default_rng(0).integers(0, 256, (4, 8, 8), dtype=np.uint8)
    assert apply_look(image, CameraLook()) is image


def test_look_full_haze_is_the_veil_and_zero_saturation_is_grey():
    image = np.random.default_rng(0).integers(0, 256, (4, 8, 8), dtype=np.uint8)
    veiled = apply_look(image, CameraLook(haze=1.0))
    assert np.array_equal(veiled, np.broadcast_to(HAZE_VEIL.astype(np.uint8)[:, None, None], image.shape))
    grey = apply_look(image, CameraLook(saturation=0.0)).astype(int)
    assert np.abs(grey[0] - grey[1]).max() <= 1 and np.abs(grey[1] - grey[2]).max() <= 1


def test_resample_keeps_a_flat_image_flat_and_reaches_the_size():
    flat = np.full((4, 30, 30), 77, np.uint8)
    for size in (20, 30, 45):
        out = resample(flat, size)
        assert out.shape == (4, size, size) and (out == 77).all()


def test_coarse_sensor_tile_has_the_city_size_and_the_same_mean_colour():
    config = small("classic")
    city = plan_city(config, "train", 4, (1, 1))
    sharp = city.render(0, 0).astype(float)
    city.look = CameraLook(source_gsd=1.0)  # 2x coarser than the 0.5 m city: rendered at 400 px, upsampled
    soft = city.render(0, 0).astype(float)
    assert soft.shape == sharp.shape
    # Same scene colours; the per-tile illumination and gains are drawn anew (up to +-6 % per band).
    assert np.abs(soft.mean(axis=(1, 2)) / sharp.mean(axis=(1, 2)) - 1).max() < 0.08
    # Soft: less pixel-to-pixel variation than the sharp render.
    assert np.abs(np.diff(soft[0], axis=1)).mean() < np.abs(np.diff(sharp[0], axis=1)).mean()


def test_style_mix_is_seeded_and_never_draws_a_zero_weight_style():
    weights = {"suburb": 1.0, "rural": 2.0, "grid": 0.0}
    drawn = [draw_style("train", s, weights) for s in range(200)]
    assert drawn == [draw_style("train", s, weights) for s in range(200)]
    assert set(drawn) == {"suburb", "rural"}
    assert 0.5 < drawn.count("rural") / drawn.count("suburb") < 4
    assert set(draw_style("train", s) for s in range(300)) == set(DEFAULT_MIX)
    with pytest.raises(ValueError, match="known styles"):
        draw_style("train", 0, {"nope": 1.0})
    with pytest.raises(ValueError, match="unknown style"):
        style_config("nope")


def test_worlds_are_numbered_cities_of_the_mix_and_refuse_unknown_keys():
    worlds = WorldsConfig.from_dict(
        {"styles": {"suburb": 1, "rural": 1}, "cities": 5, "tiles": [1, 1], "tile_size": 400, "first_seed": 7}
    )
    specs = worlds.specs()
    assert [s.seed for s in specs] == [7, 8, 9, 10, 11]
    assert {s.style for s in specs} <= {"suburb", "rural"}
    assert specs[0].path("c").name == f"train-{specs[0].style}-s7-1x1-400"
    assert CitySpec("train", 3, (1, 1), 400).path("c").name == "train-s3-1x1-400"  # classic keeps its old name
    with pytest.raises(ValueError, match="citys"):
        WorldsConfig.from_dict({"citys": 5})


def test_training_on_worlds_only_builds_them_and_needs_some_city(tmp_path):
    config = TrainConfig.from_dict(
        {
            "cache": str(tmp_path),
            "train_city": None,
            "worlds": {"styles": {"rural": 1, "downtown": 1}, "cities": 2, "tile_size": 300},
        }
    )
    cities = training_cities(config)
    assert len(cities) == 2
    styles = [json.loads((c.path / "city.json").read_text())["style"] for c in cities]
    assert styles == [CitySpec(**{"seed": 1000 + i, "style": s}).style for i, s in enumerate(styles)]
    with pytest.raises(ValueError, match="no training city"):
        training_cities(TrainConfig.from_dict({"cache": str(tmp_path), "train_city": None}))


def test_synth_cli_writes_the_style_and_refuses_an_unknown_one(tmp_path):
    done = run_cli("synth", str(tmp_path / "c"), "--style", "suburb", "--tile-size", "400", "--gsd", "0.5", "--quiet")
    assert done.returncode == 0, done.stderr
    meta = json.loads((tmp_path / "c" / "city.json").read_text())
    assert meta["style"] == "suburb" and meta["config"]["layout"] == "suburb" and meta["look"]["source_gsd"] is not None
    bad = run_cli("synth", str(tmp_path / "d"), "--style", "mars", "--quiet")
    assert bad.returncode == 2 and "mars" in bad.stderr and not (tmp_path / "d").exists()


@pytest.mark.parametrize("seed", [1, 3])
def test_highway_is_crossed_only_by_avenues_each_through_a_diamond_of_four_ramps(seed):
    config = small("highway")
    network = plan_city(config, "train", seed, (1, 1)).scene.network
    (highway,) = [s for s in network.streets if s.kind == "highway"]
    ramps = [s for s in network.streets if s.kind == "ramp"]
    through = [s for s in network.streets if s.kind in ("avenue", "boulevard")]
    hits = [s.centreline.intersection(highway.centreline) for s in through]
    crossings = [p for h in hits for p in getattr(h, "geoms", [h]) if not p.is_empty]
    inside = [p for p in crossings if shapely.box(0, 0, 400, 400).contains(p)]
    # ramp_share 1: a diamond at every crossing (ramps wholly beyond the domain's margin are clipped away)
    assert inside and 4 * len(inside) <= len(ramps) <= 4 * len(crossings)
    road = highway.roadway()
    domain = shapely.box(-80, -80, 480, 480)
    for ramp in ramps:  # each leaves the highway's outer lane and ends on an avenue (unless cut at the domain's edge)
        start, end = Point(ramp.centreline.coords[0]), Point(ramp.centreline.coords[-1])
        if domain.exterior.distance(start) > 1e-6:
            assert road.contains(start)  # on the outer lane: the ramp's edge flush with the highway's
            assert start.distance(highway.centreline) == pytest.approx(highway.width / 2 - ramp.width / 2, abs=0.5)
        if domain.exterior.distance(end) > 1e-6:
            assert min(end.distance(s.centreline) for s in through) < 1e-6
            assert end.distance(highway.centreline) > highway.width / 2 + 20
    for s in network.streets:  # every other street stops short of the highway
        if s.kind not in ("avenue", "boulevard", "highway", "ramp"):
            assert s.centreline.distance(highway.centreline) >= highway.width / 2 + config.highway_frontage - 1e-6
    assert any(m.intersects(highway.centreline) for m in network.medians)  # the median is land, not roadway
    assert not network.roadway.buffer(1e-6).contains(highway.centreline)


def test_highways_off_leave_every_other_style_untouched():
    assert all(STYLES[name].get("highways", 0) == 0 for name in STYLES if name != "highway")
    assert SynthConfig().highways == 0
