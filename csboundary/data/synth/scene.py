"""What stands on and beside the roads: sidewalks, lots, buildings, trees, cars, markings.

Everything is placed once per city in local metres, so objects that straddle a tile border are
drawn identically in both tiles. None of it changes the ground truth: lane markings,
crosswalks and driveways are painted on the ground but are not road boundaries, and trees,
cars and shadows only occlude the curb.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon
from shapely.ops import substring

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.streets import StreetNetwork

Colour = tuple[int, int, int, int]  # R, G, B, NIR

# Materials: base colour and texture roughness (noise amplitude). Vegetation is bright in NIR.
ASPHALT: Colour = (78, 80, 84, 70)
CONCRETE: Colour = (168, 163, 154, 150)
GRASS: Colour = (82, 108, 56, 205)
SOIL: Colour = (122, 108, 88, 128)
PARKING: Colour = (92, 92, 95, 82)
WHITE_PAINT: Colour = (226, 226, 220, 200)
YELLOW_PAINT: Colour = (214, 176, 64, 165)
CAR_COLOURS: tuple[Colour, ...] = (
    (235, 235, 232, 205), (25, 26, 30, 30), (160, 163, 168, 140), (100, 102, 108, 90),
    (150, 30, 30, 70), (35, 55, 120, 60), (40, 70, 50, 70), (225, 185, 40, 160), (200, 200, 205, 175),
)


@dataclass
class Painted:
    """A ground-level polygon with a colour and a texture roughness."""

    polygon: Polygon
    colour: Colour
    roughness: int


@dataclass
class Building:
    footprint: Polygon
    height: float
    roof: Colour
    detail: Polygon | None = None  # a roof structure of another shade
    detail_colour: Colour = (0, 0, 0, 0)


@dataclass
class Tree:
    x: float
    y: float
    radius: float
    colour: Colour
    shape_seed: int = 0


@dataclass
class Car:
    body: Polygon
    colour: Colour
    cabin: Polygon


@dataclass
class Scene:
    network: StreetNetwork
    ground: list[Painted] = field(default_factory=list)  # in drawing order, after the asphalt base
    markings: list[Painted] = field(default_factory=list)  # painted before blocks, so curbs clip them
    cars: list[Car] = field(default_factory=list)
    buildings: list[Building] = field(default_factory=list)
    trees: list[Tree] = field(default_factory=list)
    sun: tuple[float, float] = (0.5, -0.3)  # shadow offset per metre of height (x, y)


def _jitter(rng: np.random.Generator, colour: Colour, amount: float) -> Colour:
    scale = 1 + rng.uniform(-amount, amount)
    return tuple(int(np.clip(c * scale + rng.uniform(-6, 6), 0, 255)) for c in colour)  # type: ignore[return-value]


def _rect(origin: np.ndarray, along: np.ndarray, across: np.ndarray, length: float, width: float) -> Polygon:
    """Rectangle spanning ``origin + along*[0, length] + across*[0, width]``."""
    return Polygon([origin, origin + along * length, origin + along * length + across * width, origin + across * width])


def _centred_rect(centre: np.ndarray, along: np.ndarray, length: float, width: float) -> Polygon:
    across = np.array([-along[1], along[0]])
    return _rect(centre - along * length / 2 - across * width / 2, along, across, length, width)


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


def build_scene(cfg: SynthConfig, rng: np.random.Generator, network: StreetNetwork) -> Scene:
    """Populate every block and street of ``network``."""
    angle = rng.uniform(0, 2 * math.pi)
    reach = rng.uniform(0.25, 0.6)
    scene = Scene(network, sun=(reach * math.cos(angle), reach * math.sin(angle)))
    roadway = network.roadway
    shapely.prepare(roadway)
    _add_markings(cfg, rng, scene)
    for polygon in network.islands + network.medians:
        scene.ground.append(Painted(polygon, _jitter(rng, CONCRETE, 0.05), 5))
        inner = polygon.buffer(-0.6)
        if not inner.is_empty and rng.random() < 0.6:
            scene.ground.append(Painted(inner, _jitter(rng, GRASS, 0.1), 14))
            if rng.random() < 0.5 and inner.area > 40:
                for p in as_linestrings(inner.exterior):
                    for t in np.arange(4.0, p.length / 2, rng.uniform(8, 14)):
                        q = p.interpolate(t)
                        if inner.contains(q):
                            scene.trees.append(_tree(rng, q.x, q.y, rng.uniform(1.8, 3.0)))
    for block in network.blocks:
        _populate_block(cfg, rng, scene, block.polygon, roadway)
    _add_moving_cars(cfg, rng, scene)
    return scene


def _tree(rng: np.random.Generator, x: float, y: float, radius: float) -> Tree:
    return Tree(float(x), float(y), radius, _tree_colour(rng), int(rng.integers(2**31)))


def _tree_colour(rng: np.random.Generator) -> Colour:
    if rng.random() < 0.3:  # leafless or autumn crowns, as in the spring NYC imagery
        return _jitter(rng, (118, 106, 92, 120), 0.12)
    return _jitter(rng, (58, 86, 44, 190), 0.15)


def _populate_block(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, block: Polygon, roadway) -> None:
    sidewalk = rng.uniform(*cfg.sidewalk_width)
    scene.ground.append(Painted(block, _jitter(rng, CONCRETE, 0.06), 5))
    inner = block.buffer(-sidewalk)
    u = rng.random()
    kind = "park" if u < cfg.park_share else "lot" if u < cfg.park_share + cfg.lot_share else "residential"
    ring = LineString(shapely.orient_polygons(block).exterior.coords)  # counter-clockwise: left = inside

    # Driveways cross the sidewalk: paved like a road but not a road boundary.
    driveways: list[Polygon] = []
    if kind != "park":
        for p, d, left in _frontage(ring, lambda: rng.uniform(*cfg.driveway_spacing)):
            if rng.random() < 0.5:
                w, depth = rng.uniform(2.8, 4.0), sidewalk + rng.uniform(3.0, 8.0)
                driveways.append(_rect(p - d * w / 2 - left * 0.2, d, left, w, depth).intersection(block))
    if not inner.is_empty:
        for part in getattr(inner, "geoms", [inner]):
            if part.geom_type != "Polygon" or part.area < 20:
                continue
            ground = {"park": GRASS, "lot": PARKING, "residential": SOIL if rng.random() < 0.4 else GRASS}[kind]
            scene.ground.append(Painted(part, _jitter(rng, ground, 0.08), 14 if ground in (GRASS, SOIL) else 6))
            if kind == "park":
                _add_trees_in(rng, scene, part, density=rng.uniform(0.004, 0.012))
            else:
                _add_buildings(rng, scene, part, kind, driveways)
                if kind == "residential":
                    _add_trees_in(rng, scene, part, density=rng.uniform(0.0, 0.004))
    for driveway in driveways:
        if not driveway.is_empty:
            scene.ground.append(Painted(driveway, _jitter(rng, CONCRETE if rng.random() < 0.6 else ASPHALT, 0.08), 5))

    # Street trees along the curb; big crowns overhang the road.
    if rng.random() < 0.75:
        density = rng.uniform(0.3, 1.0)
        for p, d, left in _frontage(ring, lambda: rng.uniform(*cfg.street_tree_spacing)):
            if rng.random() < density:
                c = p + left * sidewalk * rng.uniform(0.3, 0.6)
                scene.trees.append(_tree(rng, c[0], c[1], rng.uniform(*cfg.street_tree_radius)))

    # Parked cars along the curb, on the road side.
    occupancy = rng.uniform(*cfg.parked_car_occupancy)
    for p, d, left in _frontage(ring, lambda: cfg.parked_car_spacing * rng.uniform(0.95, 1.15)):
        if rng.random() < occupancy:
            centre = p - left * rng.uniform(1.15, 1.5)
            car = _car(rng, centre, d)
            if roadway.contains(car.body):
                scene.cars.append(car)


def _car(rng: np.random.Generator, centre: np.ndarray, direction: np.ndarray) -> Car:
    length, width = rng.uniform(4.2, 5.2), rng.uniform(1.75, 2.0)
    if rng.random() < 0.06:  # vans and trucks
        length, width = rng.uniform(6.0, 9.0), rng.uniform(2.2, 2.5)
    colour = _jitter(rng, CAR_COLOURS[rng.integers(len(CAR_COLOURS))], 0.05)
    cabin_colour_centre = centre + direction * rng.uniform(-0.3, 0.1) * length
    return Car(_centred_rect(centre, direction, length, width), colour, _centred_rect(cabin_colour_centre, direction, length * 0.5, width * 0.8))


def _add_trees_in(rng: np.random.Generator, scene: Scene, area: Polygon, density: float) -> None:
    n = rng.poisson(area.area * density)
    if n == 0:
        return
    minx, miny, maxx, maxy = area.bounds
    xs, ys = rng.uniform(minx, maxx, n), rng.uniform(miny, maxy, n)
    inside = shapely.contains_xy(area, xs, ys)
    for x, y in zip(xs[inside], ys[inside]):
        scene.trees.append(_tree(rng, x, y, rng.uniform(2.0, 6.0)))


def _add_buildings(rng: np.random.Generator, scene: Scene, area: Polygon, kind: str, keep_clear: list[Polygon]) -> None:
    """Row of buildings along each side of the lot, set back from the sidewalk."""
    usable = area.buffer(-0.5)
    if usable.is_empty:
        return
    shapely.prepare(usable)
    placed: list[Polygon] = [g for g in keep_clear if not g.is_empty]
    ring = LineString(shapely.orient_polygons(area.simplify(1.0)).exterior.coords) if area.geom_type == "Polygon" else None
    if ring is None:
        return
    coords = np.asarray(ring.coords)
    wide = kind == "lot"
    for a, b in zip(coords[:-1], coords[1:]):
        edge = b - a
        length = float(np.linalg.norm(edge))
        if length < 8:
            continue
        d = edge / length
        left = np.array([-d[1], d[0]])
        t = rng.uniform(0.5, 3.0)
        while t < length:
            w = rng.uniform(15, 40) if wide else rng.uniform(5, 14)
            depth = rng.uniform(15, 35) if wide else rng.uniform(10, 24)
            setback = rng.uniform(8, 25) if wide else rng.uniform(0.0, 3.0)
            footprint = _rect(a + d * t + left * setback, d, left, min(w, length - t), depth)
            t += w + (rng.uniform(0.5, 4.0) if rng.random() < 0.35 else 0.1)  # mostly row houses
            if footprint.area < 25 or not usable.contains(footprint):
                continue
            if placed and shapely.intersects(np.array(placed, dtype=object), footprint).any():
                continue
            placed.append(footprint)
            grey = rng.uniform(70, 225)
            tint = rng.uniform(-10, 10, 3)
            roof = tuple(int(np.clip(grey + tint[i] + (25 if rng.random() < 0.1 and i == 0 else 0), 0, 255)) for i in range(3))
            roof = (*roof, int(np.clip(grey * 0.9, 0, 255)))
            building = Building(footprint, rng.uniform(8, 40) if wide else rng.uniform(6, 16), roof)  # type: ignore[arg-type]
            if rng.random() < 0.35:
                c = np.array(footprint.centroid.coords[0]) + rng.uniform(-0.2, 0.2, 2) * min(w, depth)
                building.detail = _centred_rect(c, d, min(w, depth) * rng.uniform(0.2, 0.4), min(w, depth) * rng.uniform(0.15, 0.35))
                building.detail_colour = _jitter(rng, roof, 0.3)  # type: ignore[arg-type]
            scene.buildings.append(building)


def _add_markings(cfg: SynthConfig, rng: np.random.Generator, scene: Scene) -> None:
    """Centre lines, lane dashes, stop lines and zebra crosswalks, interrupted at intersections."""
    streets = scene.network.streets
    roads = [s.roadway() for s in streets]
    tree = shapely.STRtree(roads)
    for i, s in enumerate(streets):
        others = [roads[j] for j in tree.query(s.centreline) if j != i]
        zone = shapely.union_all([o.buffer(2.0) for o in others]) if others else None
        pieces = as_linestrings(s.centreline.difference(zone)) if zone is not None else [s.centreline]
        for piece in pieces:
            if piece.length < 6:
                continue
            _lane_lines(rng, scene, s, piece)
            for at_end in (False, True):
                if rng.random() < cfg.crosswalk_share and piece.length > 20:
                    _crosswalk(rng, scene, piece, s.width, at_end)


def _offset(line: LineString, distance: float) -> list[LineString]:
    if distance == 0:
        return [line]
    return as_linestrings(line.offset_curve(distance))


def _dashes(line: LineString, dash: float, gap: float) -> list[LineString]:
    out = []
    for t in np.arange(0.0, line.length - dash, dash + gap):
        out.append(substring(line, t, t + dash))
    return out


def _lane_lines(rng: np.random.Generator, scene: Scene, street, piece: LineString) -> None:
    paint = 0.15
    if street.kind == "boulevard":
        for side in (-1, 1):
            for line in _offset(piece, side * (street.median / 2 + 3.4)):
                for dash in _dashes(line, 3.0, 6.0):
                    scene.markings.append(Painted(dash.buffer(paint / 2 + 0.02, cap_style="flat"), WHITE_PAINT, 3))
        return
    if street.width >= 12.5:
        for side in (-0.12, 0.12):
            for line in _offset(piece, side):
                scene.markings.append(Painted(line.buffer(paint / 2, cap_style="flat"), YELLOW_PAINT, 3))
        if street.width >= 16:
            for side in (-1, 1):
                for line in _offset(piece, side * street.width / 4):
                    for dash in _dashes(line, 3.0, 6.0):
                        scene.markings.append(Painted(dash.buffer(paint / 2 + 0.02, cap_style="flat"), WHITE_PAINT, 3))
    elif street.kind != "dead_end" and rng.random() < 0.5:
        for dash in _dashes(piece, 3.0, 6.0):
            scene.markings.append(Painted(dash.buffer(paint / 2 + 0.02, cap_style="flat"), WHITE_PAINT, 3))


def _crosswalk(rng: np.random.Generator, scene: Scene, piece: LineString, width: float, at_end: bool) -> None:
    """Zebra stripes across the street near one end of ``piece``, with a stop line behind."""
    t0 = piece.length - 1.0 if at_end else 1.0
    t1 = piece.length - 4.0 if at_end else 4.0
    p0, p1 = np.array(piece.interpolate(t0).coords[0]), np.array(piece.interpolate(t1).coords[0])
    along = (p1 - p0) / max(np.linalg.norm(p1 - p0), 1e-9)
    across = np.array([-along[1], along[0]])
    stripe, gap = 0.55, 0.6
    half = width / 2
    for s in np.arange(-half + 0.3, half - 0.3 - stripe, stripe + gap):
        scene.markings.append(Painted(_rect(p0 + across * s, along, across, 3.0, stripe), WHITE_PAINT, 3))
    stop = p0 + along * 4.0 - across * half
    scene.markings.append(Painted(_rect(stop, along, across, 0.45, width), WHITE_PAINT, 3))


def _add_moving_cars(cfg: SynthConfig, rng: np.random.Generator, scene: Scene) -> None:
    roadway = scene.network.roadway
    for s in scene.network.streets:
        n = rng.poisson(s.centreline.length / 1000 * cfg.moving_cars_per_km)
        for t in rng.uniform(0, s.centreline.length, n):
            p = np.array(s.centreline.interpolate(t).coords[0])
            q = np.array(s.centreline.interpolate(min(t + 1.0, s.centreline.length)).coords[0])
            if np.linalg.norm(q - p) < 1e-6:
                continue
            d = (q - p) / np.linalg.norm(q - p)
            side = rng.choice([-1, 1]) * (s.median / 2 + rng.uniform(1.8, max(2.0, s.width / 2 - s.median / 2 - 3.0)))
            centre = p + np.array([-d[1], d[0]]) * side
            car = _car(rng, centre, d if side > 0 else -d)
            if roadway.contains(car.body) and not any(car.body.intersects(c.body) for c in scene.cars[-30:]):
                scene.cars.append(car)
