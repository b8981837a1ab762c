"""Curb shapes that the buffered centrelines alone do not give (recipe steps 3 and 4 of
:mod:`.streets`): block corners rounded into curb returns, roundabouts, traffic islands,
cul-de-sac islands and boulevard medians, each a closed boundary in the ground truth.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Point, Polygon, box

from csboundary.data.synth.centrelines import QUAD_SEGS, Street
from csboundary.data.synth.config import SynthConfig, rng_share


def _crossings(streets: list[Street], min_width: float) -> list[tuple[Point, int, int]]:
    """Points where the centrelines of two streets at least ``min_width`` wide cross."""
    wide = [i for i, s in enumerate(streets) if s.width >= min_width and s.kind not in ("boulevard", "highway", "ramp")]
    out = []
    for k, i in enumerate(wide):
        for j in wide[k + 1 :]:
            hit = streets[i].centreline.intersection(streets[j].centreline)
            if not hit.is_empty and hit.geom_type == "Point":
                out.append((hit, i, j))
    return out


def roundabout_rings(
    cfg: SynthConfig, rng: np.random.Generator, streets: list[Street]
) -> list[tuple[Polygon, Polygon]]:
    """(ring disc, central island) at a share of crossings; rings never overlap one another."""
    out: list[tuple[Polygon, Polygon]] = []
    for hit, _, _ in _crossings(streets, 6.0):
        if rng.random() >= cfg.roundabout_share:
            continue
        outer = rng.uniform(*cfg.roundabout_radius)
        inner = outer - rng.uniform(6.0, 8.0)
        if inner < 3.0 or any(
            hit.distance(o.centroid) < outer + o_r + 30 for o, o_r in ((d, math.sqrt(d.area / math.pi)) for d, _ in out)
        ):
            continue
        out.append((hit.buffer(outer, quad_segs=QUAD_SEGS), hit.buffer(inner, quad_segs=QUAD_SEGS)))
    return out


def bulb_islands(cfg: SynthConfig, rng: np.random.Generator, streets: list[Street]) -> list[Polygon]:
    """Planted centre islands in a share of the cul-de-sac bulbs of radius 8 m or more."""
    out = []
    for s in streets:
        if s.bulb_radius >= 8.0 and rng_share(rng, cfg.bulb_island_share):
            out.append(
                Point(s.centreline.coords[-1]).buffer(s.bulb_radius - rng.uniform(5.5, 6.5), quad_segs=QUAD_SEGS)
            )
    return [p for p in out if p.area > math.pi * 2.0**2]


def round_convex_corners(polygon: Polygon, radius: float) -> list[Polygon]:
    """Morphological opening: rounds convex corners to ``radius``, keeps concave corners sharp."""
    if radius <= 0:
        return [polygon]
    opened = polygon.buffer(-radius, quad_segs=QUAD_SEGS).buffer(radius, quad_segs=QUAD_SEGS)
    return [p for p in getattr(opened, "geoms", [opened]) if p.geom_type == "Polygon" and p.area > 30.0]


def traffic_islands(cfg: SynthConfig, rng: np.random.Generator, streets: list[Street], roadway) -> list[Polygon]:
    """Small rounded triangles at some intersections of wide streets, well inside the roadway."""
    wide = [s for s in streets if s.width >= 10.5 and s.kind not in ("boulevard", "highway")]
    inside = roadway.buffer(-2.0)
    shapely.prepare(inside)
    islands: list[Polygon] = []
    for i, a in enumerate(wide):
        for b in wide[i + 1 :]:
            hit = a.centreline.intersection(b.centreline)
            if hit.is_empty or hit.geom_type != "Point" or rng.random() >= cfg.island_share:
                continue
            side = rng.uniform(3.5, 7.0)
            theta = rng.uniform(0, 2 * math.pi)
            corners = [
                (
                    hit.x + side * 0.58 * math.cos(theta + k * 2 * math.pi / 3),
                    hit.y + side * 0.58 * math.sin(theta + k * 2 * math.pi / 3),
                )
                for k in range(3)
            ]
            island = Polygon(corners).buffer(0.8, quad_segs=QUAD_SEGS)
            if inside.contains(island) and not any(island.distance(o) < 3.0 for o in islands):
                islands.append(island)
    return islands


def boulevard_medians(
    streets: list[Street], road_by_street: list[Polygon], roadway, avoid: list[Polygon] = ()
) -> list[Polygon]:
    """Boulevard medians, interrupted at every crossing street and roundabout (``avoid``), with rounded noses."""
    medians: list[Polygon] = []
    tree = shapely.STRtree(road_by_street)
    inside = roadway.buffer(-1.0)
    shapely.prepare(inside)
    for i, s in enumerate(streets):
        if s.median <= 0:
            continue
        strip = s.centreline.buffer(s.median / 2, cap_style="flat")
        if (
            s.kind == "highway"
        ):  # crossed by few streets: its pieces must not run out of the domain (they would fail `inside`)
            strip = strip.intersection(box(*roadway.bounds).buffer(-2.0, join_style="mitre"))
        crossing = [road_by_street[j] for j in tree.query(strip) if j != i] + [a for a in avoid if a.intersects(strip)]
        if crossing:
            strip = strip.difference(shapely.union_all([c.buffer(3.0) for c in crossing]))
        nose = s.median * 0.45
        for piece in getattr(strip, "geoms", [strip]):
            if piece.geom_type != "Polygon" or piece.area < 20.0:
                continue
            for rounded in round_convex_corners(piece, nose):
                if rounded.area > 20.0 and inside.contains(rounded):
                    medians.append(rounded)
    return medians
