"""Motorways across the grid (style knob ``highways``): a wide, curving road with a median that
only avenues cross, the streets it cuts ended short of it, and diamond interchanges of ramps.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import LineString, Point

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.centrelines import Street, offset_line, unit_vector
from csboundary.data.synth.config import SynthConfig, rng_share


def with_highways(
    cfg: SynthConfig, rng: np.random.Generator, streets: list[Street], centre: np.ndarray, half: float, bearing: float
) -> list[Street]:
    """``streets`` crossed by ``cfg.highways`` motorways: a wide, gently curving road with a
    median at an angle to the grid. Only avenues and boulevards cross it; every other street
    stops ``highway_frontage`` metres short of it (a dead end). Where an avenue crosses, a share
    of crossings get a diamond interchange: four ramps leaving the highway's outer lane
    tangentially and curving onto the avenue, with the gore between ramp and highway as land."""
    through_kinds = ("avenue", "boulevard", "highway")
    for _ in range(cfg.highways):
        angle = bearing + rng.choice([-1.0, 1.0]) * math.radians(rng.uniform(*cfg.highway_angle_deg))
        through = centre + rng.uniform(-0.25, 0.25, 2) * 2 * centre
        amp, wavelength = rng.uniform(0.0, 40.0), rng.uniform(1200.0, 2500.0)
        bend = lambda t, a=amp, wl=wavelength: a * np.sin(2 * math.pi * t / wl)  # noqa: E731
        line = offset_line(
            through,
            unit_vector(angle),
            unit_vector(angle + math.pi / 2),
            0.0,
            half + float(np.linalg.norm(through - centre)),
            bend,
        )
        median = rng.uniform(*cfg.highway_median)
        width = 2 * rng.uniform(*cfg.highway_carriageway) + median
        corridor = line.buffer(width / 2 + cfg.highway_frontage)
        kept: list[Street] = []
        tree = shapely.STRtree([s.centreline for s in streets])
        for k, street in enumerate(streets):
            if street.kind in through_kinds or not street.centreline.intersects(corridor):
                kept.append(street)
                continue
            end = street.centreline.coords[-1]
            for part in as_linestrings(street.centreline.difference(corridor)):
                touching = [j for j in tree.query(part.buffer(1.0), predicate="intersects") if j != k]
                if part.length > 30.0 and touching:  # a piece cut off from every other street would float
                    kept.append(
                        Street(
                            part,
                            street.width,
                            street.kind,
                            street.median,
                            street.bulb_radius if part.coords[-1] == end else 0.0,
                        )
                    )
        ramps: list[Street] = []
        for street in kept:
            if street.kind not in ("avenue", "boulevard"):
                continue
            hit = line.intersection(street.centreline)
            for point in getattr(hit, "geoms", [hit]):
                if not point.is_empty and point.geom_type == "Point" and rng_share(rng, cfg.ramp_share):
                    ramps.extend(_diamond_ramps(cfg, rng, line, street, point, width))
        streets = kept + [Street(line, width, "highway", median=median)] + ramps
    return streets


def _direction_at(line: LineString, point: Point) -> np.ndarray:
    """Unit direction of ``line`` where it passes ``point``."""
    t = line.project(point)
    a = np.array(line.interpolate(max(t - 2.0, 0.0)).coords[0])
    b = np.array(line.interpolate(min(t + 2.0, line.length)).coords[0])
    return (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)


def _diamond_ramps(
    cfg: SynthConfig, rng: np.random.Generator, highway: LineString, avenue: Street, crossing: Point, width: float
) -> list[Street]:
    """The four ramps of a diamond interchange where ``avenue`` crosses ``highway``: each a
    quadratic Bezier curve from the highway's outer lane, ``reach`` metres before or after the
    crossing and heading towards it, to the avenue, ``out`` metres beyond the highway's edge."""
    x = np.array(crossing.coords[0])
    h = _direction_at(highway, crossing)
    n = np.array([-h[1], h[0]])
    a = _direction_at(avenue.centreline, crossing)
    at = highway.project(crossing)

    def lane_point(distance: float, offset: float) -> np.ndarray:
        """The point ``offset`` metres left of the highway's centreline, ``distance`` along it from the crossing."""
        point = highway.interpolate(at + distance)
        d = _direction_at(highway, point)
        return np.array(point.coords[0]) + offset * np.array([-d[1], d[0]])

    ramps = []
    for side in (-1.0, 1.0):
        outward = a if float(a @ n) * side > 0 else -a
        for along in (-1.0, 1.0):
            ramp_width = rng.uniform(*cfg.ramp_width)
            reach, out = rng.uniform(130.0, 220.0), rng.uniform(45.0, 90.0)
            p0 = lane_point(along * reach, side * (width / 2 - ramp_width / 2))
            p1 = lane_point(along * 0.45 * reach, side * (width / 2 - ramp_width / 2))
            sine = max(
                abs(float(outward @ n)), 0.3
            )  # the avenue may cross obliquely: reach the same distance from the highway
            p2 = x + (width / 2 + out) / sine * outward
            t = np.linspace(0.0, 1.0, 32)[:, None]
            curve = (1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t**2 * p2
            ramps.append(Street(LineString(curve), ramp_width, "ramp"))
    return ramps
