"""The synthetic city: geometry by hand, determinism, ground truth that matches the pixels."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, Point, box

from csboundary.data import city_layout
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.data.synth.city import plan_city, synthesize_city
from csboundary.data.synth.config import SynthConfig, city_rng
from csboundary.data.synth.streets import boundary_lines, round_convex_corners

SMALL = SynthConfig(tile_size=600, gsd=0.5)  # 300 m tiles: a few blocks, renders in well under a second


@pytest.fixture(scope="module")
def small_city():
    return plan_city(SMALL, "train", 3, (1, 2))


def test_opening_rounds_convex_corners_with_the_given_radius():
    square, r = box(0, 0, 50, 50), 5.0
    (opened,) = round_convex_corners(square, r)
    # Each corner loses the region between the square corner and a quarter circle: r^2 (1 - pi/4).
    assert opened.area == pytest.approx(2500 - 4 * r * r * (1 - math.pi / 4), rel=1e-3)
    # The corner point retreats to distance r*sqrt(2) - r from the arc.
    assert Point(0, 0).distance(opened) == pytest.approx(r * math.sqrt(2) - r, abs=0.01)
    # Straight sides are untouched.
    assert opened.boundary.distance(Point(25, 0)) == pytest.approx(0, abs=1e-9)


def test_opening_keeps_concave_corners_sharp():
    ell = box(0, 0, 40, 20).union(box(0, 0, 20, 40))
    (opened,) = round_convex_corners(ell, 4.0)
    assert opened.boundary.distance(Point(20, 20)) < 0.02  # sharp up to the arc polygonisation (0.1 px)


def test_boundary_lines_are_roadway_rings_clipped_to_the_city():
    roadway = box(-10, -10, 110, 110).difference(box(20, 20, 80, 80))  # one block hole, crossing the city edge
    island = box(5, 40, 10, 45)
    roadway = roadway.difference(island)
    lines = boundary_lines(roadway, [island], [], 100.0, 100.0)
    kinds = sorted(kind for _, kind in lines)
    assert kinds == ["curb", "island"]
    assert all(line.is_closed for line, _ in lines)  # both rings lie fully inside the city
    assert sum(line.length for line, _ in lines) == pytest.approx(240 + 20)


def test_splits_never_share_a_city():
    a = city_rng("train", 5).random(4)
    b = city_rng("test", 5).random(4)
    c = city_rng("valid", 5).random(4)
    assert not np.allclose(a, b) and not np.allclose(a, c) and not np.allclose(b, c)
    with pytest.raises(ValueError):
        city_rng("nope", 1)


def test_same_seed_same_city_and_pixels(small_city):
    again = plan_city(SMALL, "train", 3, (1, 2))
    first = [line.wkb for line, _ in small_city.scene.network.boundaries]
    assert first == [line.wkb for line, _ in again.scene.network.boundaries]
    assert np.array_equal(small_city.render(0, 1), again.render(0, 1))
    other = plan_city(SMALL, "train", 4, (1, 2))
    assert first != [line.wkb for line, _ in other.scene.network.boundaries]


def test_network_has_the_features_the_benchmark_needs():
    city = plan_city(SynthConfig(tile_size=3000, gsd=0.5), "train", 0, (1, 1))  # 1.5 km square
    net = city.scene.network
    kinds = {kind for _, kind in net.boundaries}
    assert {"curb", "island", "median"} <= kinds
    assert any(line.is_closed for line, _ in net.boundaries)  # closed loops (islands, medians, whole blocks)
    assert {s.kind for s in net.streets} >= {"avenue", "street", "dead_end"}
    radii = [b.radius for b in net.blocks]
    assert min(radii) == 0.0 and 3.0 <= max(radii) <= 12.0  # sharp blocks and rounded ones
    assert city.scene.cars and city.scene.trees and city.scene.buildings and city.scene.markings


def test_ground_truth_crosses_tile_borders_unbroken(small_city):
    width, height = small_city.size_m
    seam = LineString([(width / 2, 0), (width / 2, height)])
    lines = [line for line, _ in small_city.scene.network.boundaries]
    assert any(line.crosses(seam) for line in lines)
    for line in lines:
        for end in (line.coords[0], line.coords[-1]):
            if not line.is_closed:  # open lines end only on the city's outer edge
                x, y = end
                assert min(x, y, width - x, height - y) < 1e-6


def test_markings_are_not_boundaries(small_city):
    lines = shapely.union_all([line for line, _ in small_city.scene.network.boundaries])
    lane_paint = [m.polygon for m in small_city.scene.markings if m.polygon.length > 6.0 and m.polygon.area < 0.6]
    assert lane_paint
    assert min(p.distance(lines) for p in lane_paint) > 0.5


def _pixels_at(city, row, col, xs, ys):
    image = city.render(row, col)
    frame = city.frame(row, col)
    cols = ((np.asarray(xs) - frame.x0) / frame.gsd).astype(int)
    rows = ((frame.y1 - np.asarray(ys)) / frame.gsd).astype(int)
    keep = (cols >= 0) & (cols < frame.size) & (rows >= 0) & (rows < frame.size)
    return image[:, rows[keep], cols[keep]]


def test_vegetation_is_bright_in_nir_and_roads_are_not(small_city):
    trees = [t for t in small_city.scene.trees if t.colour[3] > 150]
    tree_px = _pixels_at(small_city, 0, 0, [t.x for t in trees], [t.y for t in trees])
    road_pts = [s.centreline.interpolate(0.5, normalized=True) for s in small_city.scene.network.streets]
    road_pts = [p for p in road_pts if small_city.scene.network.roadway.contains(p.buffer(3))]
    road_px = _pixels_at(small_city, 0, 0, [p.x for p in road_pts], [p.y for p in road_pts])
    assert tree_px.shape[1] > 5 and road_px.shape[1] > 2
    assert tree_px[3].mean() > road_px[3].mean() + 50  # NIR
    assert tree_px[3].mean() > tree_px[0].mean() + 50  # NIR above red on vegetation


def test_some_curbs_are_occluded_by_trees_and_cars(small_city):
    curbs = shapely.union_all([line for line, _ in small_city.scene.network.boundaries])
    crowns = shapely.union_all([Point(t.x, t.y).buffer(t.radius) for t in small_city.scene.trees])
    cars = shapely.union_all([c.body for c in small_city.scene.cars])
    hidden_by_trees = curbs.intersection(crowns).length / curbs.length
    assert 0.01 < hidden_by_trees < 0.8
    assert curbs.distance(cars) < 1.0  # parked cars stand right at the curb


def test_written_city_round_trips(tmp_path):
    meta = synthesize_city(tmp_path / "c", seed=1, split="valid", tiles=(1, 2), config=SMALL, progress=False)
    gt = read_ground_truth(city_layout.ground_truth_path(tmp_path / "c"))
    assert gt.crs.to_epsg() == 32618
    planned = plan_city(SMALL, "valid", 1, (1, 2)).ground_truth()
    assert len(gt) == len(planned) == meta["counts"]["boundaries"]
    for a, b in zip(gt.geometry, planned.geometry):
        assert a.equals_exact(b, 1e-6)
    with Mosaic.open(city_layout.tiles_dir(tmp_path / "c")) as mosaic:
        assert (mosaic.width, mosaic.height) == (1200, 600)
        assert mosaic.crs.to_epsg() == 32618
        minx, miny, maxx, maxy = mosaic.bounds
        assert (minx, miny) == pytest.approx((SMALL.origin_x, SMALL.origin_y))
        assert gt.total_bounds[0] >= minx - 1e-6 and gt.total_bounds[2] <= maxx + 1e-6
        read = mosaic.read(mosaic.window)
        assert read.valid.all() and read.data.shape == (4, 600, 1200)


def test_interrupted_rewrite_leaves_no_finished_city(tmp_path, monkeypatch):
    out = tmp_path / "c"
    synthesize_city(out, seed=1, split="train", tiles=(1, 1), config=SMALL, progress=False)
    assert city_layout.is_city_dir(out)

    import csboundary.data.synth.city as city_module

    def crash(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(city_module, "write_ground_truth", crash)
    with pytest.raises(KeyboardInterrupt):
        synthesize_city(out, seed=2, split="train", tiles=(1, 1), config=SMALL, progress=False)
    assert not city_layout.is_city_dir(out)  # the old city.json is gone: nothing claims to be complete
    assert not [p for p in out.rglob("*") if "partial" in p.name]


def test_written_road_surface_lies_between_the_boundaries(tmp_path):
    """The road_surface layer is the roadway: on one side of every ground-truth boundary and not
    the other, so the TrainingCity's surface target changes across each boundary."""
    from csboundary.data.ground_truth import read_road_surface
    from csboundary.models.training.data import TrainingCity

    synthesize_city(tmp_path / "c", seed=1, split="valid", tiles=(1, 2), config=SMALL, progress=False)
    polygons = read_road_surface(city_layout.ground_truth_path(tmp_path / "c"))
    assert polygons and all(p.geom_type == "Polygon" for p in polygons)
    city = TrainingCity(tmp_path / "c")
    try:
        surface = city.surface_target(city.mosaic.window)
        assert 0.05 < (surface == 1).mean() < 0.6 and (surface >= 0).all()
        gt = read_ground_truth(city_layout.ground_truth_path(tmp_path / "c"))
        differs, total = 0, 0
        for line in gt.geometry:
            for t in np.arange(2.0, line.length - 2.0, 5.0):  # metres along the boundary
                p, q = np.array(line.interpolate(t).coords[0]), np.array(line.interpolate(t + 0.5).coords[0])
                normal = np.array([-(q - p)[1], (q - p)[0]]) / np.linalg.norm(q - p)
                sides = []
                for sign in (1, -1):
                    x, y = p + sign * 1.5 * normal  # 3 px of 0.5 m either side
                    col, row = city.mosaic.world_to_pixel(x, y)
                    if 0 <= int(row) < surface.shape[0] and 0 <= int(col) < surface.shape[1]:
                        sides.append(surface[int(row), int(col)])
                if len(sides) == 2:
                    total += 1
                    differs += sides[0] != sides[1]
        assert total > 100 and differs / total > 0.95
        outside = city.surface_target(city.mosaic.window.__class__(-10, -10, 20, 20))
        assert (outside[:10, :] == -1).all() and (outside[10:, 10:] >= 0).all()  # beyond the city: unknown
    finally:
        city.close()


def test_a_city_without_a_road_surface_layer_has_an_unknown_surface(tmp_path):
    from csboundary.data.ground_truth import read_ground_truth as read
    from csboundary.data.ground_truth import write_ground_truth
    from csboundary.models.training.data import TrainingCity

    synthesize_city(tmp_path / "c", seed=1, split="valid", tiles=(1, 1), config=SMALL, progress=False)
    path = city_layout.ground_truth_path(tmp_path / "c")
    write_ground_truth(path, read(path))  # boundaries only, as an imported city has
    with TrainingCity(tmp_path / "c") as city:
        assert city.surface is None and (city.surface_target(city.mosaic.window) == -1).all()
