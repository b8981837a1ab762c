"""What stands on and beside the roads: sidewalks, lots, buildings, trees, cars, markings.

Everything is placed once per city in local metres, so objects that straddle a tile border are
drawn identically in both tiles. None of it changes the ground truth: lane markings,
crosswalks and driveways are painted on the ground but are not road boundaries, and trees,
cars and shadows only occlude the curb.

This module places a whole scene; what it places comes from one module per kind of thing:
:mod:`.materials` (colours), :mod:`.objects` (the scene's data), :mod:`.markings` (paint and
wear on the roadway), :mod:`.blocks` (each block, with :mod:`.buildings`, :mod:`.roofs`,
:mod:`.grounds` and :mod:`.vegetation`) and :mod:`.vehicles` (cars). The names other modules
and tests use are importable from here.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.blocks import populate_block
from csboundary.data.synth.config import SynthConfig
from csboundary.data.synth.markings import add_road_markings, add_road_wear
from csboundary.data.synth.materials import (
    ASPHALT,
    CAR_COLOURS,
    CAR_PHOTO_COLOURS,
    CONCRETE,
    COURTS,
    CROP_COLOURS,
    DRIVEWAYS,
    FENCES,
    GRASS,
    GRAVEL,
    HEDGE,
    PARKING,
    ROAD_MATERIALS,
    ROOF_PALETTES,
    SIDEWALK_MATERIALS,
    SOIL,
    TAR_ROOFS,
    WATER,
    WHITE_PAINT,
    WINDOW,
    YELLOW_PAINT,
    Colour,
    jitter_colour,
)
from csboundary.data.synth.objects import Building, Car, Painted, Scene, Tree
from csboundary.data.synth.roofs import roof_facets
from csboundary.data.synth.shapes import centred_rect
from csboundary.data.synth.streets import StreetNetwork
from csboundary.data.synth.vegetation import add_canopy, make_tree
from csboundary.data.synth.vehicles import add_moving_cars

# what importers take from here besides build_scene (add_canopy and centred_rect: by tests)
__all__ = [
    "ASPHALT",
    "CAR_COLOURS",
    "CAR_PHOTO_COLOURS",
    "CONCRETE",
    "COURTS",
    "CROP_COLOURS",
    "DRIVEWAYS",
    "FENCES",
    "GRASS",
    "GRAVEL",
    "HEDGE",
    "PARKING",
    "ROAD_MATERIALS",
    "ROOF_PALETTES",
    "SIDEWALK_MATERIALS",
    "SOIL",
    "TAR_ROOFS",
    "WATER",
    "WHITE_PAINT",
    "WINDOW",
    "YELLOW_PAINT",
    "Building",
    "Car",
    "Colour",
    "Painted",
    "Scene",
    "Tree",
    "add_canopy",
    "centred_rect",
    "build_scene",
    "roof_facets",
]


def build_scene(cfg: SynthConfig, rng: np.random.Generator, network: StreetNetwork) -> Scene:
    """Populate every block and street of ``network``."""
    angle = rng.uniform(0, 2 * math.pi)
    reach = rng.uniform(*cfg.sun_reach)
    scene = Scene(network, sun=(reach * math.cos(angle), reach * math.sin(angle)))
    if cfg.road_materials != ("asphalt",):
        scene.road = jitter_colour(
            rng, ROAD_MATERIALS[cfg.road_materials[int(rng.integers(len(cfg.road_materials)))]], 0.06
        )
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
        add_road_wear(cfg, rng, scene)
    add_road_markings(cfg, rng, scene)
    for polygon in network.islands + network.medians:
        scene.ground.append(Painted(polygon, jitter_colour(rng, CONCRETE, 0.05), 5))
        inner = polygon.buffer(-0.6)
        if not inner.is_empty and rng.random() < 0.6:
            scene.ground.append(Painted(inner, jitter_colour(rng, GRASS, 0.1), 14))
            if rng.random() < 0.5 and inner.area > 40:
                for p in as_linestrings(inner.exterior):
                    for t in np.arange(4.0, p.length / 2, rng.uniform(8, 14)):
                        q = p.interpolate(t)
                        if inner.contains(q):
                            scene.trees.append(make_tree(rng, q.x, q.y, rng.uniform(1.8, 3.0)))
    for block in network.blocks:
        populate_block(cfg, rng, scene, block.polygon, roadway, sidewalk_colour)
    add_moving_cars(cfg, rng, scene)
    if cfg.bare_tree_share > 0:
        for tree in scene.trees:
            if rng.random() < cfg.bare_tree_share:
                tree.bare = True
                tree.colour = jitter_colour(rng, (112, 100, 88, 110), 0.12)
    return scene
