"""Cars: one car's body, cabin and colour, and the moving traffic along every street. Parked
cars are placed where they park (:mod:`.blocks`, :mod:`.grounds`, :mod:`.buildings`).
"""

from __future__ import annotations

import numpy as np

from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.materials import CAR_COLOURS, CAR_PHOTO_COLOURS, jitter_colour
from csboundary.data.synth.objects import Car, Scene
from csboundary.data.synth.shapes import centred_rect


def make_car(rng: np.random.Generator, centre: np.ndarray, direction: np.ndarray, detail: bool = False) -> Car:
    """One car (now and then a van or truck) centred on ``centre`` facing ``direction``: a body,
    a cabin and a colour (photographed colours and windows when ``detail``)."""
    length, width = rng.uniform(4.2, 5.2), rng.uniform(1.75, 2.0)
    if rng.random() < 0.06:  # vans and trucks
        length, width = rng.uniform(6.0, 9.0), rng.uniform(2.2, 2.5)
    if detail:
        weights = np.array([w for _, w in CAR_PHOTO_COLOURS])
        colour = jitter_colour(
            rng, CAR_PHOTO_COLOURS[int(rng.choice(len(weights), p=weights / weights.sum()))][0], 0.06
        )
        return Car(
            centred_rect(centre, direction, length, width),
            colour,
            centred_rect(centre, direction, length * 0.5, width * 0.8),
            True,
        )
    colour = jitter_colour(rng, CAR_COLOURS[rng.integers(len(CAR_COLOURS))], 0.05)
    cabin_colour_centre = centre + direction * rng.uniform(-0.3, 0.1) * length
    return Car(
        centred_rect(centre, direction, length, width),
        colour,
        centred_rect(cabin_colour_centre, direction, length * 0.5, width * 0.8),
    )


def add_moving_cars(cfg: SynthConfig, rng: np.random.Generator, scene: Scene) -> None:
    """Traffic in the lanes of every street (``moving_cars_per_km``), none overlapping another."""
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
            car = make_car(rng, centre, d if side > 0 else -d, cfg.car_detail)
            if roadway.contains(car.body) and not any(car.body.intersects(c.body) for c in scene.cars[-30:]):
                scene.cars.append(car)
