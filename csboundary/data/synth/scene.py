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
import shapely.affinity
from shapely.geometry import LineString, Polygon
from shapely.ops import substring

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.streets import StreetNetwork, rng_share

Colour = tuple[int, int, int, int]  # R, G, B, NIR

# Materials: base colour and texture roughness (noise amplitude). Vegetation is bright in NIR.
ASPHALT: Colour = (78, 80, 84, 70)
CONCRETE: Colour = (168, 163, 154, 150)
GRASS: Colour = (82, 108, 56, 205)
SOIL: Colour = (122, 108, 88, 128)
PARKING: Colour = (92, 92, 95, 82)
WHITE_PAINT: Colour = (226, 226, 220, 200)
YELLOW_PAINT: Colour = (214, 176, 64, 165)
GRAVEL: Colour = (140, 128, 110, 125)
HEDGE: Colour = (46, 72, 38, 175)
FENCES: tuple[Colour, ...] = ((150, 128, 98, 120), (122, 120, 116, 110), (62, 58, 54, 60), (205, 200, 190, 175))
WATER: Colour = (70, 162, 192, 40)  # pools: bright cyan, dark in NIR
DRIVEWAYS: tuple[Colour, ...] = (ASPHALT, (58, 60, 64, 54), CONCRETE, PARKING, (150, 145, 138, 132))
# Per-city material choices (config ``road_materials`` / ``sidewalk_materials`` / ``roof_palette``).
ROAD_MATERIALS: dict[str, Colour] = {
    "asphalt": ASPHALT,
    "asphalt_new": (46, 48, 52, 44),
    "asphalt_old": (118, 117, 113, 104),
    "asphalt_warm": (98, 90, 82, 80),
    "concrete_road": (150, 148, 141, 134),
}
SIDEWALK_MATERIALS: dict[str, Colour] = {
    "concrete": CONCRETE,
    "concrete_dark": (132, 129, 123, 118),
    "pavers_red": (152, 108, 92, 118),
    "pavers_grey": (141, 139, 134, 126),
    "asphalt_walk": (96, 96, 98, 86),
}
ROOF_PALETTES = ("grey", "warm", "dark", "mixed", "tar")  # tar: flat tar, gravel and membrane roofs
CROP_COLOURS: tuple[Colour, ...] = ((96, 128, 60, 215), (150, 140, 84, 170), (118, 100, 74, 120), (70, 104, 48, 225), (176, 160, 104, 160))
# Car colours as seen in dense-city photographs: mostly white, black, silver and grey, a few saturated.
CAR_PHOTO_COLOURS: tuple[tuple[Colour, float], ...] = (
    ((232, 233, 230, 200), 0.24), ((28, 29, 33, 30), 0.2), ((178, 181, 185, 150), 0.14), ((105, 108, 114, 95), 0.14),
    ((52, 58, 70, 55), 0.07), ((150, 32, 32, 70), 0.06), ((32, 58, 118, 60), 0.05), ((120, 96, 70, 90), 0.04),
    ((225, 190, 45, 160), 0.03), ((60, 96, 60, 80), 0.03),
)
WINDOW: Colour = (38, 44, 52, 40)  # windshields and rear windows: dark glass
TAR_ROOFS: tuple[Colour, ...] = ((120, 120, 118, 108), (64, 64, 66, 58), (212, 214, 212, 190), (186, 186, 182, 165), (158, 150, 138, 140), (92, 90, 88, 80))
COURTS: tuple[Colour, ...] = ((50, 78, 50, 60), (140, 78, 66, 96), (70, 108, 82, 90), (134, 84, 72, 90))  # turf, then courts: red, green, red
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
    facets: list[tuple[Polygon, float]] = field(default_factory=list)  # pitched roof: facet, brightness factor
    ridge: Polygon | None = None  # pitched roof: the ridge line as a thin strip
    parapet: Colour | None = None  # flat roof: a rim of this colour, ``parapet_width`` wide, along the outline
    parapet_width: float = 0.0
    roof_items: list[tuple[Polygon, Colour]] = field(default_factory=list)  # units, tanks, wells and their shadows


@dataclass
class Tree:
    x: float
    y: float
    radius: float
    colour: Colour
    shape_seed: int = 0
    lobes: int = 5  # crown lobes (render: 5 = simple crown, more = lobes lit from the sun's side)
    bare: bool = False  # leafless: branches over a see-through crown (``bare_tree_share``)


@dataclass
class Car:
    body: Polygon
    colour: Colour
    cabin: Polygon
    detail: bool = False  # drawn with windows, a lit roof and a shadow (``car_detail``)


@dataclass
class Scene:
    network: StreetNetwork
    ground: list[Painted] = field(default_factory=list)  # in drawing order, after the asphalt base
    markings: list[Painted] = field(default_factory=list)  # painted before blocks, so curbs clip them
    cars: list[Car] = field(default_factory=list)
    buildings: list[Building] = field(default_factory=list)
    trees: list[Tree] = field(default_factory=list)
    sun: tuple[float, float] = (0.5, -0.3)  # shadow offset per metre of height (x, y)
    road: Colour = ASPHALT  # the roadway's material, painted under everything
    lean: tuple[float, float] = (0.0, 0.0)  # relief displacement of roofs, metres per metre of height (x, y)
    texture: float = 0.0  # ``photo_texture``: amplitude of the texture at every scale


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
    reach = rng.uniform(*cfg.sun_reach)
    scene = Scene(network, sun=(reach * math.cos(angle), reach * math.sin(angle)))
    if cfg.road_materials != ("asphalt",):
        scene.road = _jitter(rng, ROAD_MATERIALS[cfg.road_materials[int(rng.integers(len(cfg.road_materials)))]], 0.06)
    sidewalk_colour = CONCRETE
    if cfg.sidewalk_materials != ("concrete",):
        sidewalk_colour = SIDEWALK_MATERIALS[cfg.sidewalk_materials[int(rng.integers(len(cfg.sidewalk_materials)))]]
    roadway = network.roadway
    shapely.prepare(roadway)
    scene.texture = cfg.photo_texture
    if cfg.relief_lean[1] > 0:
        lean_angle, lean = rng.uniform(0, 2 * math.pi), rng.uniform(*cfg.relief_lean)
        scene.lean = (lean * math.cos(lean_angle), lean * math.sin(lean_angle))
    if cfg.road_wear_per_km > 0:
        _add_road_wear(cfg, rng, scene)
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
        _populate_block(cfg, rng, scene, block.polygon, roadway, sidewalk_colour)
    _add_moving_cars(cfg, rng, scene)
    if cfg.bare_tree_share > 0:
        for tree in scene.trees:
            if rng.random() < cfg.bare_tree_share:
                tree.bare = True
                tree.colour = _jitter(rng, (112, 100, 88, 110), 0.12)
    return scene


def _tree(rng: np.random.Generator, x: float, y: float, radius: float, lobes: int = 5) -> Tree:
    return Tree(float(x), float(y), radius, _tree_colour(rng), int(rng.integers(2**31)), lobes)


def _tree_colour(rng: np.random.Generator) -> Colour:
    if rng.random() < 0.3:  # leafless or autumn crowns, as in the spring NYC imagery
        return _jitter(rng, (118, 106, 92, 120), 0.12)
    return _jitter(rng, (58, 86, 44, 190), 0.15)


def _edge_strips(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, block: Polygon, sidewalk_colour: Colour) -> float:
    """Paint what lies between the road and a block's interior; return its width in metres.

    Raised curb (default): a gutter pan on the road side (``gutter_share``), then the block in
    sidewalk material, then a grass verge between curb and sidewalk (``verge_share``). No curb
    (rural): a gravel shoulder on the block side and grass or soil behind it. The ground truth is
    the block's outline in every case: the curb, or the asphalt's edge.
    """
    if not cfg.raised_curb:
        shoulder = rng.uniform(*cfg.shoulder_width)
        scene.ground.append(Painted(block, _jitter(rng, GRAVEL if rng.random() < 0.6 else SOIL, 0.1), 12))
        return shoulder
    if rng_share(rng, cfg.gutter_share):
        gutter = block.buffer(rng.uniform(*cfg.gutter_width), quad_segs=8).difference(block)
        scene.ground.append(Painted(gutter, _jitter(rng, CONCRETE, 0.08), 4))
    if cfg.sidewalk_materials == ("concrete",):
        scene.ground.append(Painted(block, _jitter(rng, CONCRETE, 0.06), 5))
    else:
        scene.ground.append(Painted(block, _jitter(rng, sidewalk_colour, 0.06), 5))
    verge = rng.uniform(*cfg.verge_width) if rng_share(rng, cfg.verge_share) else 0.0
    if verge > 0:
        strip = block.difference(block.buffer(-verge))
        scene.ground.append(Painted(strip, _jitter(rng, GRASS, 0.1), 14))
    return verge


def _populate_block(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, block: Polygon, roadway, sidewalk_colour: Colour = CONCRETE) -> None:
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
                driveways.append(_rect(p - d * w / 2 - left * 0.2, d, left, w, depth).intersection(block))
    if not inner.is_empty:
        for part in getattr(inner, "geoms", [inner]):
            if part.geom_type != "Polygon" or part.area < 20:
                continue
            if kind == "field":
                scene.ground.append(Painted(part, _jitter(rng, CROP_COLOURS[int(rng.integers(len(CROP_COLOURS)))], 0.1), 18))
                continue
            ground = {"park": GRASS, "lot": PARKING, "residential": SOIL if rng.random() < 0.4 else GRASS}[kind]
            if kind == "residential" and rng_share(rng, cfg.paved_yard_share):
                ground = _jitter(rng, CONCRETE if rng.random() < 0.5 else PARKING, 0.1)
            scene.ground.append(Painted(part, _jitter(rng, ground, 0.08), 14 if ground in (GRASS, SOIL) else 6))  # type: ignore[arg-type]
            if kind == "park" and rng_share(rng, cfg.court_share):
                _add_court(rng, scene, part)
                _add_trees_in(rng, scene, part.difference(part.buffer(-3.0)), density=0.01)
            elif kind == "park":
                _add_trees_in(rng, scene, part, density=rng.uniform(0.004, 0.012))
            elif kind == "lot" and cfg.lot_stalls:
                _add_stalls(cfg, rng, scene, part)
            else:
                _add_buildings(cfg, rng, scene, part, kind, driveways, block, sidewalk)
                if kind == "residential":
                    _add_trees_in(rng, scene, part, density=rng.uniform(0.0, 0.004), lobes=cfg.crown_lobes)
                    if cfg.yard_canopy[1] > 0:
                        _add_canopy(rng, scene, part, rng.uniform(*cfg.yard_canopy), cfg.crown_lobes)
    for driveway in driveways:
        if not driveway.is_empty:
            scene.ground.append(Painted(driveway, _jitter(rng, CONCRETE if rng.random() < 0.6 else ASPHALT, 0.08), 5))

    # Street trees along the curb; big crowns overhang the road.
    if rng.random() < cfg.street_tree_share:
        density = rng.uniform(0.3, 1.0)
        for p, d, left in _frontage(ring, lambda: rng.uniform(*cfg.street_tree_spacing)):
            if rng.random() < density:
                c = p + left * max(sidewalk, 2.0) * rng.uniform(*cfg.street_tree_setback)
                scene.trees.append(_tree(rng, c[0], c[1], rng.uniform(*cfg.street_tree_radius), cfg.crown_lobes))
                if cfg.tree_pits:
                    pit = _centred_rect(c, d, rng.uniform(1.2, 1.8), rng.uniform(1.1, 1.5)).intersection(block)
                    scene.ground.append(Painted(pit, _jitter(rng, (88, 76, 62, 110), 0.12), 16))

    # Parked cars along the curb, on the road side.
    occupancy = rng.uniform(*cfg.parked_car_occupancy)
    for p, d, left in _frontage(ring, lambda: cfg.parked_car_spacing * rng.uniform(0.95, 1.15)):
        if rng.random() < occupancy:
            centre = p - left * rng.uniform(1.15, 1.5)
            car = _car(rng, centre, d, cfg.car_detail)
            if roadway.contains(car.body):
                scene.cars.append(car)


def _car(rng: np.random.Generator, centre: np.ndarray, direction: np.ndarray, detail: bool = False) -> Car:
    length, width = rng.uniform(4.2, 5.2), rng.uniform(1.75, 2.0)
    if rng.random() < 0.06:  # vans and trucks
        length, width = rng.uniform(6.0, 9.0), rng.uniform(2.2, 2.5)
    if detail:
        weights = np.array([w for _, w in CAR_PHOTO_COLOURS])
        colour = _jitter(rng, CAR_PHOTO_COLOURS[int(rng.choice(len(weights), p=weights / weights.sum()))][0], 0.06)
        return Car(_centred_rect(centre, direction, length, width), colour, _centred_rect(centre, direction, length * 0.5, width * 0.8), True)
    colour = _jitter(rng, CAR_COLOURS[rng.integers(len(CAR_COLOURS))], 0.05)
    cabin_colour_centre = centre + direction * rng.uniform(-0.3, 0.1) * length
    return Car(_centred_rect(centre, direction, length, width), colour, _centred_rect(cabin_colour_centre, direction, length * 0.5, width * 0.8))


def _add_trees_in(rng: np.random.Generator, scene: Scene, area: Polygon, density: float, lobes: int = 5) -> None:
    n = rng.poisson(area.area * density)
    if n == 0:
        return
    minx, miny, maxx, maxy = area.bounds
    xs, ys = rng.uniform(minx, maxx, n), rng.uniform(miny, maxy, n)
    inside = shapely.contains_xy(area, xs, ys)
    for x, y in zip(xs[inside], ys[inside]):
        scene.trees.append(_tree(rng, x, y, rng.uniform(2.0, 6.0), lobes))


def _add_canopy(rng: np.random.Generator, scene: Scene, area: Polygon, cover: float, lobes: int) -> None:
    """Clumps of big, touching crowns until their summed crown area reaches ``cover`` of ``area``.

    Real suburbs hide much of each yard (and often the curb) under a continuous canopy whose
    outline against the lawn is as sharp as a road edge; isolated round crowns never teach that.
    """
    minx, miny, maxx, maxy = area.bounds
    goal, crowns = cover * area.area, 0.0
    for _ in range(200):  # clumps; bounded so a thin yard cannot loop for ever
        if crowns >= goal:
            return
        centre = rng.uniform((minx, miny), (maxx, maxy))
        if not area.contains(shapely.Point(centre)):
            continue
        for _ in range(int(rng.integers(2, 9))):
            x, y = centre + rng.normal(0.0, 4.5, 2)
            radius = rng.uniform(3.0, 7.0)
            scene.trees.append(_tree(rng, x, y, radius, lobes))
            crowns += math.pi * radius**2


def _roof(rng: np.random.Generator, palette: str) -> Colour:
    """A roof colour: grey concrete and tar (the original palette), warm tiles and shingles, or dark."""
    if palette == "mixed":
        palette = ("grey", "warm", "dark")[int(rng.integers(3))]
    if palette == "warm":
        base = ((168, 84, 60), (130, 96, 80), (110, 70, 55), (150, 130, 110))[int(rng.integers(4))]
        rgb = [int(np.clip(c * rng.uniform(0.8, 1.15), 0, 255)) for c in base]
        return (*rgb, int(np.clip(sum(rgb) / 3 * 0.9, 0, 255)))  # type: ignore[return-value]
    if palette == "dark":
        g = rng.uniform(35, 80)
        return (int(g), int(g), int(g + rng.uniform(0, 8)), int(g * 0.9))
    grey = rng.uniform(70, 225)
    tint = rng.uniform(-10, 10, 3)
    roof = tuple(int(np.clip(grey + tint[i] + (25 if rng.random() < 0.1 and i == 0 else 0), 0, 255)) for i in range(3))
    return (*roof, int(np.clip(grey * 0.9, 0, 255)))  # type: ignore[return-value]


def roof_facets(origin: np.ndarray, along: np.ndarray, across: np.ndarray, length: float, width: float, hip: bool,
                sun: tuple[float, float]) -> tuple[list[tuple[Polygon, float]], Polygon | None]:
    """The facets of a pitched roof over the rectangle ``origin + along*[0, length] +
    across*[0, width]`` (unit ``along``, ``across``) and its ridge.

    The ridge runs along the longer side at mid-width; a gable roof has two facets, a hip roof
    four (45-degree hips: the ridge is inset by half the width at each end, a point on a square).
    Each facet comes with a brightness factor 1 + 0.3 cos(angle between its outward direction and
    the sun), the sun lying opposite the shadow offset ``sun``. The ridge is a 0.24 m strip, or
    None where it shrinks to a point.
    """
    p0 = np.asarray(origin, float)
    if width > length:  # relabel so that ``along`` is the long side (same rectangle)
        p0, along, across, length, width = p0 + along * length, across, -along, width, length
    p1, p3 = p0 + along * length, p0 + across * width
    p2 = p1 + across * width
    inset = width / 2 if hip else 0.0
    r0 = p0 + across * width / 2 + along * inset
    r1 = p0 + across * width / 2 + along * (length - inset)
    faces = [([p0, p1, r1, r0], -across), ([r0, r1, p2, p3], across)]
    if hip:
        faces += [([p0, r0, p3], -along), ([p1, p2, r1], along)]
    norm = math.hypot(*sun)
    towards_sun = -np.asarray(sun, float) / norm if norm > 0 else np.zeros(2)
    facets = [(Polygon(corners), 1.0 + 0.3 * float(np.dot(normal, towards_sun))) for corners, normal in faces]
    ridge = LineString([r0, r1]).buffer(0.12, cap_style="flat") if length - 2 * inset > 0.2 else None
    return facets, ridge


def _yard(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, yard: dict[str, list], origin: np.ndarray, d: np.ndarray,
          left: np.ndarray, width: float, gap: float, setback: float, depth: float, front: float, block: Polygon | None,
          area: Polygon) -> None:
    """A house's lot (residential knobs): its own lawn shade, a fence or hedge on the lot line,
    a pool behind the house, a driveway from the curb to the house with maybe a car on it.
    ``origin`` is the lot's front corner on the sidewalk side, ``d`` along the street, ``left``
    into the block; ``front`` the sidewalk strip between the lot and the curb. Painted into
    ``yard``'s lists (lawns first, then fences and pools, then paving), no ground truth."""
    if rng_share(rng, cfg.lawn_patch_share):
        lot = _rect(origin, d, left, width + gap, setback + depth + rng.uniform(4.0, 14.0)).intersection(area)
        base = GRASS if rng.random() < 0.75 else (118, 124, 70, 170)  # green or dry lawn
        yard["lawns"].append(Painted(lot, _jitter(rng, base, 0.16), 14))
    if gap > 1.0 and rng_share(rng, cfg.lot_fence_share):
        start = origin + d * (width + gap / 2)
        line = LineString([start + left * setback * rng.uniform(0.0, 1.0), start + left * (setback + depth + rng.uniform(2.0, 15.0))])
        if rng.random() < 0.4:
            yard["things"].append(Painted(line.buffer(rng.uniform(0.5, 0.9)).intersection(area), _jitter(rng, HEDGE, 0.12), 22))
        else:
            fence = FENCES[int(rng.integers(len(FENCES)))]
            yard["things"].append(Painted(line.buffer(rng.uniform(0.07, 0.15), cap_style="flat").intersection(area), _jitter(rng, fence, 0.08), 3))
    if rng_share(rng, cfg.pool_share):
        centre = origin + d * width * rng.uniform(0.3, 0.7) + left * (setback + depth + rng.uniform(3.5, 7.0))
        pool = _centred_rect(centre, d, rng.uniform(5.0, 10.0), rng.uniform(3.0, 5.0))
        if area.contains(pool.buffer(1.0)):
            yard["things"].append(Painted(pool.buffer(0.9, join_style="mitre"), _jitter(rng, CONCRETE, 0.06), 4))
            yard["things"].append(Painted(pool.buffer(0.4), _jitter(rng, WATER, 0.1), 3))
    if setback > 2.0 and rng_share(rng, cfg.house_driveway_share):
        dw = rng.uniform(2.8, 6.0)  # one or two cars wide
        s = max(0.0, width - dw) * float(rng.random() < 0.5)  # at one end of the house (the garage)
        paving = _rect(origin + d * s - left * (front + 0.3), d, left, dw, front + 0.3 + setback + 0.5)
        paving = paving.intersection(block) if block is not None else paving.intersection(area)
        yard["paved"].append(Painted(paving, _jitter(rng, DRIVEWAYS[int(rng.integers(len(DRIVEWAYS)))], 0.08), 5))
        if setback > 5.5 and rng.random() < 0.4:
            scene.cars.append(_car(rng, origin + d * (s + dw / 2) + left * (setback - rng.uniform(2.7, 3.4)), left, cfg.car_detail))


def _add_buildings(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, area: Polygon, kind: str, keep_clear: list[Polygon],
                   block: Polygon | None = None, front: float = 0.0) -> None:
    """Row of buildings along each side of the lot, set back from the sidewalk (``front`` wide,
    between ``area`` and the curb, ``block``'s outline); with their yards where the style has them."""
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
    yard: dict[str, list] = {"lawns": [], "things": [], "paved": []}
    for a, b in zip(coords[:-1], coords[1:]):
        edge = b - a
        length = float(np.linalg.norm(edge))
        if length < 8:
            continue
        d = edge / length
        left = np.array([-d[1], d[0]])
        t = rng.uniform(0.5, 3.0)
        while t < length:
            w = rng.uniform(15, 40) if wide else rng.uniform(*cfg.house_width)
            depth = rng.uniform(15, 35) if wide else rng.uniform(*cfg.house_depth)
            setback = rng.uniform(8, 25) if wide else rng.uniform(*cfg.house_setback)
            t0, fw = t, min(w, length - t)
            footprint = _rect(a + d * t + left * setback, d, left, fw, depth)
            gap = rng.uniform(*cfg.house_gap) if rng.random() < cfg.house_gap_share else 0.1  # mostly row houses
            t += w + gap
            if footprint.area < 25 or not usable.contains(footprint):
                continue
            if placed and shapely.intersects(np.array(placed, dtype=object), footprint).any():
                continue
            if cfg.building_share < 1 and rng.random() >= cfg.building_share:
                continue
            placed.append(footprint)
            roof = _roof(rng, cfg.roof_palette) if cfg.roof_palette != "tar" else _jitter(rng, TAR_ROOFS[int(rng.integers(len(TAR_ROOFS)))], 0.1)
            height = rng.uniform(8, 40) if wide else rng.uniform(*cfg.house_height)
            if rng_share(rng, cfg.tower_share):
                height = rng.uniform(*cfg.tower_height)
            building = Building(footprint, height, roof)
            if not wide and rng_share(rng, cfg.pitched_roof_share):
                building.facets, building.ridge = roof_facets(a + d * t0 + left * setback, d, left, fw, depth, rng.random() < 0.5, scene.sun)
            elif rng.random() < 0.35:
                c = np.array(footprint.centroid.coords[0]) + rng.uniform(-0.2, 0.2, 2) * min(w, depth)
                building.detail = _centred_rect(c, d, min(w, depth) * rng.uniform(0.2, 0.4), min(w, depth) * rng.uniform(0.15, 0.35))
                building.detail_colour = _jitter(rng, roof, 0.3)  # type: ignore[arg-type]
            if not building.facets and rng_share(rng, cfg.flat_roof_detail):
                _roof_details(rng, building, d, scene.sun)
            scene.buildings.append(building)
            if not wide:
                _yard(cfg, rng, scene, yard, a + d * t0, d, left, fw, gap, setback, depth, front, block, area)
    scene.ground.extend(yard["lawns"] + yard["things"] + yard["paved"])


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
            if s.width >= 18 and s.kind in ("avenue", "boulevard") and rng_share(rng, cfg.bus_lane_share):
                _bus_or_bike_lane(rng, scene, s, piece)
            _lane_lines(cfg, rng, scene, s, piece)
            for at_end in (False, True):
                if s.kind not in ("highway", "ramp") and rng.random() < cfg.crosswalk_share and piece.length > 20:
                    _crosswalk(rng, scene, piece, s.width, at_end)


def _bus_or_bike_lane(rng: np.random.Generator, scene: Scene, street, piece: LineString) -> None:
    """A red bus lane (3.4 m) or a green bike lane (1.8 m, white edge lines) on one or both
    sides, just beyond the parking lane (2.5 m from the curb): paint, not a boundary."""
    bus = rng.random() < 0.6
    width, colour = (3.4, (150, 72, 62, 80)) if bus else (1.8, (72, 128, 84, 90))
    sides = (-1, 1) if rng.random() < 0.4 else (int(rng.choice([-1, 1])),)
    for side in sides:
        for line in _offset(piece, side * (street.width / 2 - 2.5 - width / 2)):
            scene.markings.append(Painted(line.buffer(width / 2, cap_style="flat"), _jitter(rng, colour, 0.1), 5))
            if not bus:
                for edge in (-1, 1):
                    for e in _offset(line, edge * width / 2):
                        scene.markings.append(Painted(e.buffer(0.08, cap_style="flat"), WHITE_PAINT, 3))


def _offset(line: LineString, distance: float) -> list[LineString]:
    if distance == 0:
        return [line]
    return as_linestrings(line.offset_curve(distance))


def _dashes(line: LineString, dash: float, gap: float) -> list[LineString]:
    out = []
    for t in np.arange(0.0, line.length - dash, dash + gap):
        out.append(substring(line, t, t + dash))
    return out


def _lane_lines(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, street, piece: LineString) -> None:
    paint = 0.15
    if rng_share(rng, cfg.edge_line_share):  # solid white lines just inside the asphalt's edge
        for side in (-1, 1):
            for line in _offset(piece, side * (street.width / 2 - rng.uniform(0.25, 0.5))):
                scene.markings.append(Painted(line.buffer(paint / 2 + 0.03, cap_style="flat"), WHITE_PAINT, 3))
    if cfg.lane_paint_share < 1 and rng.random() >= cfg.lane_paint_share:
        return
    if street.kind == "highway":  # dashed lanes of 3.6 m, solid lines along the median and the edge
        carriageway = (street.width - street.median) / 2
        for side in (-1, 1):
            for k in range(1, max(1, int(carriageway // 3.6))):
                for line in _offset(piece, side * (street.median / 2 + 3.6 * k)):
                    for dash in _dashes(line, 3.0, 9.0):
                        scene.markings.append(Painted(dash.buffer(paint / 2 + 0.02, cap_style="flat"), WHITE_PAINT, 3))
            for offset in (street.median / 2 + 0.5, street.width / 2 - 0.5):
                for line in _offset(piece, side * offset):
                    scene.markings.append(Painted(line.buffer(paint / 2 + 0.03, cap_style="flat"), WHITE_PAINT, 3))
        return
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
            car = _car(rng, centre, d if side > 0 else -d, cfg.car_detail)
            if roadway.contains(car.body) and not any(car.body.intersects(c.body) for c in scene.cars[-30:]):
                scene.cars.append(car)


def _roof_details(rng: np.random.Generator, b: Building, d: np.ndarray, sun: tuple[float, float]) -> None:
    """A flat roof as photographed: a parapet rim, a light well or two, rooftop units and a water
    tank on the taller ones, each item with its short shadow on the roof (``flat_roof_detail``)."""
    roof = b.roof
    b.parapet = _scaled_colour(roof, 1.3 if rng.random() < 0.5 else 0.72)
    b.parapet_width = float(rng.uniform(0.3, 0.6))
    inner = b.footprint.buffer(-1.2)
    if inner.is_empty:
        return
    minx, miny, maxx, maxy = inner.bounds
    sun_v = np.asarray(sun, float)

    def spot():
        for _ in range(6):
            p = rng.uniform((minx, miny), (maxx, maxy))
            if inner.contains(shapely.Point(p)):
                return p
        return None

    for _ in range(int(rng.integers(0, 4))):  # patches of newer or older roofing
        p = spot()
        if p is not None:
            patch = _centred_rect(p, d, rng.uniform(3.0, 12.0), rng.uniform(3.0, 10.0)).intersection(inner)
            b.roof_items.append((patch, _scaled_colour(roof, rng.uniform(0.75, 1.25))))
    if rng.random() < 0.45:  # light well / courtyard: a small dark shaft
        p = spot()
        if p is not None:
            well = _centred_rect(p, d, rng.uniform(2.0, 4.5), rng.uniform(1.5, 3.5)).intersection(inner)
            b.roof_items.append((well, _jitter(rng, (34, 34, 36, 30), 0.15)))
    for _ in range(int(rng.poisson(min(b.footprint.area / 120.0, 6.0)))):
        p = spot()
        if p is None:
            continue
        unit = _centred_rect(p, d, rng.uniform(0.8, 3.0), rng.uniform(0.8, 2.2))
        tall = rng.uniform(0.6, 2.0)
        b.roof_items.append((shapely.affinity.translate(unit, *(sun_v * tall)).intersection(b.footprint), _scaled_colour(roof, 0.5)))
        b.roof_items.append((unit, _jitter(rng, (188, 190, 192, 170) if rng.random() < 0.7 else (120, 122, 126, 110), 0.1)))
    if b.height > 14 and rng.random() < 0.3:  # a timber water tank on its stand
        p = spot()
        if p is not None:
            r = rng.uniform(1.4, 2.4)
            tank = shapely.Point(p).buffer(r, quad_segs=6)
            b.roof_items.append((shapely.affinity.translate(tank, *(sun_v * 5.0)).intersection(b.footprint), _scaled_colour(roof, 0.45)))
            b.roof_items.append((tank, _jitter(rng, (118, 100, 82, 100), 0.12)))
            b.roof_items.append((shapely.Point(p).buffer(r * 0.55, quad_segs=6), _jitter(rng, (96, 82, 68, 80), 0.1)))


def _scaled_colour(colour: Colour, factor: float) -> Colour:
    return tuple(int(np.clip(c * factor, 0, 255)) for c in colour)  # type: ignore[return-value]


def _add_road_wear(cfg: SynthConfig, rng: np.random.Generator, scene: Scene) -> None:
    """Asphalt patches of another shade, dark tar seams and cracks and manhole covers on the
    roadway (``road_wear_per_km``), painted first so lane paint lies on them and curbs clip them."""
    road = scene.road
    for s in scene.network.streets:
        line = s.centreline
        for t in rng.uniform(0, line.length, rng.poisson(line.length / 1000 * cfg.road_wear_per_km)):
            p = np.array(line.interpolate(t).coords[0])
            q = np.array(line.interpolate(min(t + 1.0, line.length)).coords[0])
            if np.linalg.norm(q - p) < 1e-6:
                continue
            d = (q - p) / np.linalg.norm(q - p)
            n = np.array([-d[1], d[0]])
            off = rng.uniform(-0.5, 0.5) * s.width
            u = rng.random()
            if u < 0.35:  # a patch of newer or older asphalt (a utility cut, a resurfaced lane)
                patch = _centred_rect(p + n * off, d, rng.uniform(2.0, 25.0), rng.uniform(1.0, max(1.2, s.width / 2)))
                scene.markings.append(Painted(patch, _scaled_colour(road, rng.uniform(0.7, 1.3)), int(rng.integers(3, 8))))
            elif u < 0.8:  # a crack or tar seam: a thin dark wandering line
                pts = [p + n * off]
                heading = d * rng.choice([-1, 1]) if rng.random() < 0.6 else n
                for _ in range(int(rng.integers(3, 12))):
                    heading = heading + rng.normal(0, 0.35, 2)
                    heading /= np.linalg.norm(heading)
                    pts.append(pts[-1] + heading * rng.uniform(0.8, 3.0))
                seam = LineString(pts).buffer(rng.uniform(0.03, 0.08), cap_style="flat")
                scene.markings.append(Painted(seam, _scaled_colour(road, rng.uniform(0.65, 0.85)), 2))
            elif u < 0.9:  # a long seam between paving passes
                seam = _centred_rect(p + n * off, d, rng.uniform(15.0, 60.0), rng.uniform(0.1, 0.25))
                scene.markings.append(Painted(seam, _scaled_colour(road, rng.uniform(0.45, 0.7)), 2))
            else:  # a manhole cover
                scene.markings.append(Painted(shapely.Point(p + n * off).buffer(0.35, quad_segs=4), _scaled_colour(road, rng.uniform(0.5, 0.8)), 3))


def _axes(area: Polygon) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Centre, long and short unit axes and their lengths of ``area``'s minimum rotated rectangle."""
    box = np.asarray(area.minimum_rotated_rectangle.exterior.coords)[:4]
    e1, e2 = box[1] - box[0], box[2] - box[1]
    if np.linalg.norm(e1) < np.linalg.norm(e2):
        e1, e2 = e2, e1
    c = box.mean(axis=0)
    return c, e1 / np.linalg.norm(e1), e2 / np.linalg.norm(e2), float(np.linalg.norm(e1)), float(np.linalg.norm(e2))


def _add_court(rng: np.random.Generator, scene: Scene, area: Polygon) -> None:
    """A schoolyard or park as a sports field or a grid of courts: paving, turf or red/green
    courts and their white lines (outline, halfway line, centre circle, boxes). Painted, never a
    road boundary."""
    scene.ground.append(Painted(area, _jitter(rng, (128, 124, 118, 110) if rng.random() < 0.6 else PARKING, 0.08), 8))
    c, u, v, lu, lv = _axes(area)
    margin = rng.uniform(2.0, 6.0)
    lu, lv = lu - 2 * margin, lv - 2 * margin
    if lu < 12 or lv < 8:
        return
    if rng.random() < 0.4 and lu > 50 and lv > 30:  # one turf field
        courts = [(c, min(lu, 105.0), min(lv, 68.0), COURTS[0])]
    else:  # a grid of basketball / handball courts, one surface colour for the yard
        length, width = rng.uniform(24.0, 30.0), rng.uniform(13.0, 16.0)
        colour = COURTS[int(rng.integers(1, len(COURTS)))]
        nu, nv = max(1, int(lu // (length + 2.0))), max(1, int(lv // (width + 2.0)))
        courts = [(c + u * (i - (nu - 1) / 2) * (length + 2.0) + v * (j - (nv - 1) / 2) * (width + 2.0), length, width, colour)
                  for i in range(nu) for j in range(nv)]
    for centre, length, width, colour in courts:
        court = _centred_rect(centre, u, length, width).intersection(area)
        if court.is_empty or court.area < 50:
            continue
        scene.ground.append(Painted(court, _jitter(rng, colour, 0.08), 7))
        inset = _centred_rect(centre, u, length - 1.0, width - 1.0)
        lines = [inset.exterior, LineString([centre - v * (width / 2 - 0.5), centre + v * (width / 2 - 0.5)]),
                 shapely.Point(centre).buffer(min(width, length) * 0.13).exterior]
        for side in (-1, 1):  # goal boxes or keys at both ends
            end = centre + u * side * (length / 2 - 0.5)
            lines.append(LineString([end - v * width * 0.2, end - v * width * 0.2 - u * side * length * 0.14,
                                     end + v * width * 0.2 - u * side * length * 0.14, end + v * width * 0.2]))
        for line in lines:
            scene.ground.append(Painted(line.buffer(0.07).intersection(area), WHITE_PAINT, 3))


def _add_stalls(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, area: Polygon) -> None:
    """A parking lot of painted stalls in double rows along the lot's long axis, cars in some of
    them (``lot_stalls``). The lot's outline and its paint are not road boundaries."""
    c, u, v, lu, lv = _axes(area)
    inner = area.buffer(-1.0)
    if inner.is_empty:
        return
    shapely.prepare(inner)
    occupancy = rng.uniform(0.3, 0.95)
    stall, depth, aisle = rng.uniform(2.5, 2.8), 5.0, rng.uniform(6.5, 7.5)
    lines, cars = [], []
    for r0 in np.arange(-lv / 2 + 1.0, lv / 2 - depth, 2 * depth + aisle):
        for s0 in np.arange(-lu / 2 + 1.0, lu / 2 - stall, stall):
            for row in (r0, r0 + depth) if r0 + 2 * depth < lv / 2 else (r0,):
                base = c + u * s0 + v * row
                lines.append(LineString([base, base + v * depth]))
                if rng.random() < occupancy:
                    cars.append((base + u * stall / 2 + v * depth / 2, v))
    for line in lines:
        if inner.contains(line):
            scene.ground.append(Painted(line.buffer(0.06, cap_style="flat"), WHITE_PAINT, 3))
    for centre, d in cars:
        car = _car(rng, centre, d, cfg.car_detail)
        if inner.contains(car.body):
            scene.cars.append(car)
