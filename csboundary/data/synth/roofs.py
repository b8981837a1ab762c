"""What a roof looks like from above: its colour by palette, the sunlit and shaded facets of a
pitched roof, and the clutter on a flat one (parapet, units, tanks, light wells).
"""

from __future__ import annotations

import math

import numpy as np
import shapely
import shapely.affinity
from shapely.geometry import LineString, Polygon

from csboundary.data.synth.materials import Colour, jitter_colour, scaled_colour
from csboundary.data.synth.objects import Building
from csboundary.data.synth.shapes import centred_rect


def roof_colour(rng: np.random.Generator, palette: str) -> Colour:
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


def roof_facets(
    origin: np.ndarray,
    along: np.ndarray,
    across: np.ndarray,
    length: float,
    width: float,
    hip: bool,
    sun: tuple[float, float],
) -> tuple[list[tuple[Polygon, float]], Polygon | None]:
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


def add_flat_roof_details(rng: np.random.Generator, b: Building, d: np.ndarray, sun: tuple[float, float]) -> None:
    """A flat roof as photographed: a parapet rim, a light well or two, rooftop units and a water
    tank on the taller ones, each item with its short shadow on the roof (``flat_roof_detail``)."""
    roof = b.roof
    b.parapet = scaled_colour(roof, 1.3 if rng.random() < 0.5 else 0.72)
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
            patch = centred_rect(p, d, rng.uniform(3.0, 12.0), rng.uniform(3.0, 10.0)).intersection(inner)
            b.roof_items.append((patch, scaled_colour(roof, rng.uniform(0.75, 1.25))))
    if rng.random() < 0.45:  # light well / courtyard: a small dark shaft
        p = spot()
        if p is not None:
            well = centred_rect(p, d, rng.uniform(2.0, 4.5), rng.uniform(1.5, 3.5)).intersection(inner)
            b.roof_items.append((well, jitter_colour(rng, (34, 34, 36, 30), 0.15)))
    for _ in range(int(rng.poisson(min(b.footprint.area / 120.0, 6.0)))):
        p = spot()
        if p is None:
            continue
        unit = centred_rect(p, d, rng.uniform(0.8, 3.0), rng.uniform(0.8, 2.2))
        tall = rng.uniform(0.6, 2.0)
        b.roof_items.append(
            (shapely.affinity.translate(unit, *(sun_v * tall)).intersection(b.footprint), scaled_colour(roof, 0.5))
        )
        b.roof_items.append(
            (unit, jitter_colour(rng, (188, 190, 192, 170) if rng.random() < 0.7 else (120, 122, 126, 110), 0.1))
        )
    if b.height > 14 and rng.random() < 0.3:  # a timber water tank on its stand
        p = spot()
        if p is not None:
            r = rng.uniform(1.4, 2.4)
            tank = shapely.Point(p).buffer(r, quad_segs=6)
            b.roof_items.append(
                (shapely.affinity.translate(tank, *(sun_v * 5.0)).intersection(b.footprint), scaled_colour(roof, 0.45))
            )
            b.roof_items.append((tank, jitter_colour(rng, (118, 100, 82, 100), 0.12)))
            b.roof_items.append(
                (shapely.Point(p).buffer(r * 0.55, quad_segs=6), jitter_colour(rng, (96, 82, 68, 80), 0.1))
            )
