"""One block of land, from the curb inwards: curb-side strips (gutter, sidewalk, verge, or a
rural shoulder), driveways, the interior as park, lot, field or houses (handed to
:mod:`.grounds`, :mod:`.buildings`, :mod:`.vegetation`), street trees and cars parked at the curb.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from csboundary.data.synth.buildings import add_buildings
from csboundary.data.synth.config import SynthConfig, rng_share
from csboundary.data.synth.grounds import add_parking_stalls, add_sports_ground
from csboundary.data.synth.materials import (
    ASPHALT,
    CONCRETE,
    CROP_COLOURS,
    GRASS,
    GRAVEL,
    PARKING,
    SOIL,
    Colour,
    jitter_colour,
)
from csboundary.data.synth.objects import Painted, Scene
from csboundary.data.synth.shapes import centred_rect, rect
from csboundary.data.synth.vegetation import add_canopy, make_tree, scatter_trees
from csboundary.data.synth.vehicles import make_car


def _frontage(ring: LineString, spacing_fn, step_back: float = 3.0):
    """Yield (point, unit direction, left normal) at straight places along a ring.

    A place is straight when the direction changes by less than 4 degrees over +-``step_back``
    metres: curb returns and corners are skipped, which is where nothing is parked.
    """
    length = ring.length
    t = spacing_fn()
    while t < length - step_back:
        a, p, b = (np.array(ring.interpolate(v).coords[0]) for v in (t - step_back, t, t + step_back))
        d1, d2 = p - a, b - p
        n1, n2 = np.linalg.norm(d1), np.linalg.norm(d2)
        if t > step_back and n1 > 0 and n2 > 0:
            cos = float(np.dot(d1, d2) / (n1 * n2))
            if cos > math.cos(math.radians(4)):
                d = (b - a) / np.linalg.norm(b - a)
                yield p, d, np.array([-d[1], d[0]])
        t += spacing_fn()


def _edge_strips(
    cfg: SynthConfig, rng: np.random.Generator, scene: Scene, block: Polygon, sidewalk_colour: Colour
) -> float:
    """Paint what lies between the road and a block's interior; return its width in metres.

    Raised curb (default): a gutter pan on the road side (``gutter_share``), then the block in
    sidewalk material, then a grass verge between curb and sidewalk (``verge_share``). No curb
    (rural): a gravel shoulder on the block side and grass or soil behind it. The ground truth is
    the block's outline in every case: the curb, or the asphalt's edge.
    """
    if not cfg.raised_curb:
        shoulder = rng.uniform(*cfg.shoulder_width)
        scene.ground.append(Painted(block, jitter_colour(rng, GRAVEL if rng.random() < 0.6 else SOIL, 0.1), 12))
        return shoulder
    if rng_share(rng, cfg.gutter_share):
        gutter = block.buffer(rng.uniform(*cfg.gutter_width), quad_segs=8).difference(block)
        scene.ground.append(Painted(gutter, jitter_colour(rng, CONCRETE, 0.08), 4))
    if cfg.sidewalk_materials == ("concrete",):
        scene.ground.append(Painted(block, jitter_colour(rng, CONCRETE, 0.06), 5))
    else:
        scene.ground.append(Painted(block, jitter_colour(rng, sidewalk_colour, 0.06), 5))
    verge = rng.uniform(*cfg.verge_width) if rng_share(rng, cfg.verge_share) else 0.0
    if verge > 0:
        strip = block.difference(block.buffer(-verge))
        scene.ground.append(Painted(strip, jitter_colour(rng, GRASS, 0.1), 14))
    return verge


def populate_block(
    cfg: SynthConfig,
    rng: np.random.Generator,
    scene: Scene,
    block: Polygon,
    roadway,
    sidewalk_colour: Colour = CONCRETE,
) -> None:
    """Fill one block: sidewalk and edge strips, then a park (with courts), a parking lot, a
    field or lots of buildings and yards, with driveways, street trees and cars parked at the curb."""
    sidewalk = rng.uniform(*cfg.sidewalk_width)
    if rng_share(rng, cfg.bare_block_share):
        sidewalk = 0.0  # the lawn runs to the curb
    sidewalk += _edge_strips(cfg, rng, scene, block, sidewalk_colour)
    inner = block.buffer(-sidewalk)
    u = rng.random()
    kind = "park" if u < cfg.park_share else "lot" if u < cfg.park_share + cfg.lot_share else "residential"
    if kind == "residential" and rng_share(rng, cfg.field_share):
        kind = "field"
    ring = LineString(shapely.orient_polygons(block).exterior.coords)  # counter-clockwise: left = inside

    # Driveways cross the sidewalk: paved like a road but not a road boundary.
    driveways: list[Polygon] = []
    if kind not in ("park", "field"):
        for p, d, left in _frontage(ring, lambda: rng.uniform(*cfg.driveway_spacing)):
            if rng.random() < 0.5:
                w, depth = rng.uniform(2.8, 4.0), sidewalk + rng.uniform(3.0, 8.0)
                driveways.append(rect(p - d * w / 2 - left * 0.2, d, left, w, depth).intersection(block))
    if not inner.is_empty:
        for part in getattr(inner, "geoms", [inner]):
            if part.geom_type != "Polygon" or part.area < 20:
                continue
            if kind == "field":
                scene.ground.append(
                    Painted(part, jitter_colour(rng, CROP_COLOURS[int(rng.integers(len(CROP_COLOURS)))], 0.1), 18)
                )
                continue
            ground = {"park": GRASS, "lot": PARKING, "residential": SOIL if rng.random() < 0.4 else GRASS}[kind]
            if kind == "residential" and rng_share(rng, cfg.paved_yard_share):
                ground = jitter_colour(rng, CONCRETE if rng.random() < 0.5 else PARKING, 0.1)
            scene.ground.append(Painted(part, jitter_colour(rng, ground, 0.08), 14 if ground in (GRASS, SOIL) else 6))  # type: ignore[arg-type]
            if kind == "park" and rng_share(rng, cfg.court_share):
                add_sports_ground(rng, scene, part)
                scatter_trees(rng, scene, part.difference(part.buffer(-3.0)), density=0.01)
            elif kind == "park":
                scatter_trees(rng, scene, part, density=rng.uniform(0.004, 0.012))
            elif kind == "lot" and cfg.lot_stalls:
                add_parking_stalls(cfg, rng, scene, part)
            else:
                add_buildings(cfg, rng, scene, part, kind, driveways, block, sidewalk)
                if kind == "residential":
                    scatter_trees(rng, scene, part, density=rng.uniform(0.0, 0.004), lobes=cfg.crown_lobes)
                    if cfg.yard_canopy[1] > 0:
                        add_canopy(rng, scene, part, rng.uniform(*cfg.yard_canopy), cfg.crown_lobes)
    for driveway in driveways:
        if not driveway.is_empty:
            scene.ground.append(
                Painted(driveway, jitter_colour(rng, CONCRETE if rng.random() < 0.6 else ASPHALT, 0.08), 5)
            )

    # Street trees along the curb; big crowns overhang the road.
    if rng.random() < cfg.street_tree_share:
        density = rng.uniform(0.3, 1.0)
        for p, d, left in _frontage(ring, lambda: rng.uniform(*cfg.street_tree_spacing)):
            if rng.random() < density:
                c = p + left * max(sidewalk, 2.0) * rng.uniform(*cfg.street_tree_setback)
                scene.trees.append(make_tree(rng, c[0], c[1], rng.uniform(*cfg.street_tree_radius), cfg.crown_lobes))
                if cfg.tree_pits:
                    pit = centred_rect(c, d, rng.uniform(1.2, 1.8), rng.uniform(1.1, 1.5)).intersection(block)
                    scene.ground.append(Painted(pit, jitter_colour(rng, (88, 76, 62, 110), 0.12), 16))

    # Parked cars along the curb, on the road side.
    occupancy = rng.uniform(*cfg.parked_car_occupancy)
    for p, d, left in _frontage(ring, lambda: cfg.parked_car_spacing * rng.uniform(0.95, 1.15)):
        if rng.random() < occupancy:
            centre = p - left * rng.uniform(1.15, 1.5)
            car = make_car(rng, centre, d, cfg.car_detail)
            if roadway.contains(car.body):
                scene.cars.append(car)
