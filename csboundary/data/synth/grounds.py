"""Open grounds inside blocks: sports fields and courts with their white lines in parks, and
parking lots painted into stalls with cars in them. Painted, never a road boundary.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.materials import COURTS, PARKING, WHITE_PAINT, jitter_colour
from csboundary.data.synth.objects import Painted, Scene
from csboundary.data.synth.shapes import centred_rect
from csboundary.data.synth.vehicles import make_car


def _axes(area: Polygon) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Centre, long and short unit axes and their lengths of ``area``'s minimum rotated rectangle."""
    box = np.asarray(area.minimum_rotated_rectangle.exterior.coords)[:4]
    e1, e2 = box[1] - box[0], box[2] - box[1]
    if np.linalg.norm(e1) < np.linalg.norm(e2):
        e1, e2 = e2, e1
    c = box.mean(axis=0)
    return c, e1 / np.linalg.norm(e1), e2 / np.linalg.norm(e2), float(np.linalg.norm(e1)), float(np.linalg.norm(e2))


def add_sports_ground(rng: np.random.Generator, scene: Scene, area: Polygon) -> None:
    """A schoolyard or park as a sports field or a grid of courts: paving, turf or red/green
    courts and their white lines (outline, halfway line, centre circle, boxes). Painted, never a
    road boundary."""
    scene.ground.append(
        Painted(area, jitter_colour(rng, (128, 124, 118, 110) if rng.random() < 0.6 else PARKING, 0.08), 8)
    )
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
        courts = [
            (
                c + u * (i - (nu - 1) / 2) * (length + 2.0) + v * (j - (nv - 1) / 2) * (width + 2.0),
                length,
                width,
                colour,
            )
            for i in range(nu)
            for j in range(nv)
        ]
    for centre, length, width, colour in courts:
        court = centred_rect(centre, u, length, width).intersection(area)
        if court.is_empty or court.area < 50:
            continue
        scene.ground.append(Painted(court, jitter_colour(rng, colour, 0.08), 7))
        inset = centred_rect(centre, u, length - 1.0, width - 1.0)
        lines = [
            inset.exterior,
            LineString([centre - v * (width / 2 - 0.5), centre + v * (width / 2 - 0.5)]),
            shapely.Point(centre).buffer(min(width, length) * 0.13).exterior,
        ]
        for side in (-1, 1):  # goal boxes or keys at both ends
            end = centre + u * side * (length / 2 - 0.5)
            lines.append(
                LineString(
                    [
                        end - v * width * 0.2,
                        end - v * width * 0.2 - u * side * length * 0.14,
                        end + v * width * 0.2 - u * side * length * 0.14,
                        end + v * width * 0.2,
                    ]
                )
            )
        for line in lines:
            scene.ground.append(Painted(line.buffer(0.07).intersection(area), WHITE_PAINT, 3))


def add_parking_stalls(cfg: SynthConfig, rng: np.random.Generator, scene: Scene, area: Polygon) -> None:
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
        car = make_car(rng, centre, d, cfg.car_detail)
        if inner.contains(car.body):
            scene.cars.append(car)
