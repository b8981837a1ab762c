"""Trees: single crowns, crowns scattered over parks and yards, and clumped canopy; their colour
(leafy, or bare and autumn shades). Trees occlude the curb but never change the ground truth.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Polygon

from csboundary.data.synth.materials import Colour, jitter_colour
from csboundary.data.synth.objects import Scene, Tree


def make_tree(rng: np.random.Generator, x: float, y: float, radius: float, lobes: int = 5) -> Tree:
    """A tree at (``x``, ``y``) with a random crown colour and its own crown-shape seed."""
    return Tree(float(x), float(y), radius, _tree_colour(rng), int(rng.integers(2**31)), lobes)


def _tree_colour(rng: np.random.Generator) -> Colour:
    if rng.random() < 0.3:  # leafless or autumn crowns, as in the spring NYC imagery
        return jitter_colour(rng, (118, 106, 92, 120), 0.12)
    return jitter_colour(rng, (58, 86, 44, 190), 0.15)


def scatter_trees(rng: np.random.Generator, scene: Scene, area: Polygon, density: float, lobes: int = 5) -> None:
    """Trees scattered at random over ``area``, ``density`` per square metre on average."""
    n = rng.poisson(area.area * density)
    if n == 0:
        return
    minx, miny, maxx, maxy = area.bounds
    xs, ys = rng.uniform(minx, maxx, n), rng.uniform(miny, maxy, n)
    inside = shapely.contains_xy(area, xs, ys)
    for x, y in zip(xs[inside], ys[inside]):
        scene.trees.append(make_tree(rng, x, y, rng.uniform(2.0, 6.0), lobes))


def add_canopy(rng: np.random.Generator, scene: Scene, area: Polygon, cover: float, lobes: int) -> None:
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
            scene.trees.append(make_tree(rng, x, y, radius, lobes))
            crowns += math.pi * radius**2
