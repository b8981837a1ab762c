"""Buildings in rows along a block's edges, set back from the sidewalk, with a roof each
(:mod:`.roofs`); for houses also their yards: lawns, fences and hedges, pools and driveways.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from csboundary.data.synth.config import SynthConfig, rng_share
from csboundary.data.synth.materials import CONCRETE, DRIVEWAYS, FENCES, GRASS, HEDGE, TAR_ROOFS, WATER, jitter_colour
from csboundary.data.synth.objects import Building, Painted, Scene
from csboundary.data.synth.roofs import add_flat_roof_details, roof_colour, roof_facets
from csboundary.data.synth.shapes import centred_rect, rect
from csboundary.data.synth.vehicles import make_car


def _yard(
    cfg: SynthConfig,
    rng: np.random.Generator,
    scene: Scene,
    yard: dict[str, list],
    origin: np.ndarray,
    d: np.ndarray,
    left: np.ndarray,
    width: float,
    gap: float,
    setback: float,
    depth: float,
    front: float,
    block: Polygon | None,
    area: Polygon,
) -> None:
    """A house's lot (residential knobs): its own lawn shade, a fence or hedge on the lot line,
    a pool behind the house, a driveway from the curb to the house with maybe a car on it.
    ``origin`` is the lot's front corner on the sidewalk side, ``d`` along the street, ``left``
    into the block; ``front`` the sidewalk strip between the lot and the curb. Painted into
    ``yard``'s lists (lawns first, then fences and pools, then paving), no ground truth."""
    if rng_share(rng, cfg.lawn_patch_share):
        lot = rect(origin, d, left, width + gap, setback + depth + rng.uniform(4.0, 14.0)).intersection(area)
        base = GRASS if rng.random() < 0.75 else (118, 124, 70, 170)  # green or dry lawn
        yard["lawns"].append(Painted(lot, jitter_colour(rng, base, 0.16), 14))
    if gap > 1.0 and rng_share(rng, cfg.lot_fence_share):
        start = origin + d * (width + gap / 2)
        line = LineString(
            [start + left * setback * rng.uniform(0.0, 1.0), start + left * (setback + depth + rng.uniform(2.0, 15.0))]
        )
        if rng.random() < 0.4:
            yard["things"].append(
                Painted(line.buffer(rng.uniform(0.5, 0.9)).intersection(area), jitter_colour(rng, HEDGE, 0.12), 22)
            )
        else:
            fence = FENCES[int(rng.integers(len(FENCES)))]
            yard["things"].append(
                Painted(
                    line.buffer(rng.uniform(0.07, 0.15), cap_style="flat").intersection(area),
                    jitter_colour(rng, fence, 0.08),
                    3,
                )
            )
    if rng_share(rng, cfg.pool_share):
        centre = origin + d * width * rng.uniform(0.3, 0.7) + left * (setback + depth + rng.uniform(3.5, 7.0))
        pool = centred_rect(centre, d, rng.uniform(5.0, 10.0), rng.uniform(3.0, 5.0))
        if area.contains(pool.buffer(1.0)):
            yard["things"].append(Painted(pool.buffer(0.9, join_style="mitre"), jitter_colour(rng, CONCRETE, 0.06), 4))
            yard["things"].append(Painted(pool.buffer(0.4), jitter_colour(rng, WATER, 0.1), 3))
    if setback > 2.0 and rng_share(rng, cfg.house_driveway_share):
        dw = rng.uniform(2.8, 6.0)  # one or two cars wide
        s = max(0.0, width - dw) * float(rng.random() < 0.5)  # at one end of the house (the garage)
        paving = rect(origin + d * s - left * (front + 0.3), d, left, dw, front + 0.3 + setback + 0.5)
        paving = paving.intersection(block) if block is not None else paving.intersection(area)
        yard["paved"].append(Painted(paving, jitter_colour(rng, DRIVEWAYS[int(rng.integers(len(DRIVEWAYS)))], 0.08), 5))
        if setback > 5.5 and rng.random() < 0.4:
            scene.cars.append(
                make_car(
                    rng, origin + d * (s + dw / 2) + left * (setback - rng.uniform(2.7, 3.4)), left, cfg.car_detail
                )
            )


def add_buildings(
    cfg: SynthConfig,
    rng: np.random.Generator,
    scene: Scene,
    area: Polygon,
    kind: str,
    keep_clear: list[Polygon],
    block: Polygon | None = None,
    front: float = 0.0,
) -> None:
    """Row of buildings along each side of the lot, set back from the sidewalk (``front`` wide,
    between ``area`` and the curb, ``block``'s outline); with their yards where the style has them."""
    usable = area.buffer(-0.5)
    if usable.is_empty:
        return
    shapely.prepare(usable)
    placed: list[Polygon] = [g for g in keep_clear if not g.is_empty]
    ring = (
        LineString(shapely.orient_polygons(area.simplify(1.0)).exterior.coords) if area.geom_type == "Polygon" else None
    )
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
            footprint = rect(a + d * t + left * setback, d, left, fw, depth)
            gap = rng.uniform(*cfg.house_gap) if rng.random() < cfg.house_gap_share else 0.1  # mostly row houses
            t += w + gap
            if footprint.area < 25 or not usable.contains(footprint):
                continue
            if placed and shapely.intersects(np.array(placed, dtype=object), footprint).any():
                continue
            if cfg.building_share < 1 and rng.random() >= cfg.building_share:
                continue
            placed.append(footprint)
            roof = (
                roof_colour(rng, cfg.roof_palette)
                if cfg.roof_palette != "tar"
                else jitter_colour(rng, TAR_ROOFS[int(rng.integers(len(TAR_ROOFS)))], 0.1)
            )
            height = rng.uniform(8, 40) if wide else rng.uniform(*cfg.house_height)
            if rng_share(rng, cfg.tower_share):
                height = rng.uniform(*cfg.tower_height)
            building = Building(footprint, height, roof)
            if not wide and rng_share(rng, cfg.pitched_roof_share):
                building.facets, building.ridge = roof_facets(
                    a + d * t0 + left * setback, d, left, fw, depth, rng.random() < 0.5, scene.sun
                )
            elif rng.random() < 0.35:
                c = np.array(footprint.centroid.coords[0]) + rng.uniform(-0.2, 0.2, 2) * min(w, depth)
                building.detail = centred_rect(
                    c, d, min(w, depth) * rng.uniform(0.2, 0.4), min(w, depth) * rng.uniform(0.15, 0.35)
                )
                building.detail_colour = jitter_colour(rng, roof, 0.3)  # type: ignore[arg-type]
            if not building.facets and rng_share(rng, cfg.flat_roof_detail):
                add_flat_roof_details(rng, building, d, scene.sun)
            scene.buildings.append(building)
            if not wide:
                _yard(cfg, rng, scene, yard, a + d * t0, d, left, fw, gap, setback, depth, front, block, area)
    scene.ground.extend(yard["lawns"] + yard["things"] + yard["paved"])
