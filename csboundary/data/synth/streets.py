"""The street network of a synthetic city, its roadway polygon and hence the ground truth.

Recipe (local metres, origin at the city's south-west corner, y to the north):

1. A grid of avenues at a random bearing and cross streets roughly perpendicular to them, with
   varied spacings and widths; some cross streets curve, some segments are dropped (large
   blocks) or cut short (dead ends, some with a round cul-de-sac); a few diagonal streets;
   optionally motorways that only avenues cross, with diamond interchanges (``with_highways``).
2. The raw roadway is the union of every centreline buffered by its half-width.
3. Blocks are the domain minus the raw roadway. Each block is opened (negative then positive
   buffer) by its own curb-return radius (3-12 m), which rounds its convex corners; a share of
   blocks keep sharp corners. The roadway is recomputed from the rounded blocks.
4. Traffic islands at some intersections and medians along boulevards are cut out of the
   roadway, so they are closed boundary loops.
5. The ground truth is the rings of the final roadway, clipped to the city's extent.

This module runs the recipe; the steps live apart: :mod:`.centrelines` (what a street is),
:mod:`.layout` with :mod:`.highways` and :mod:`.suburbs` (step 1), :mod:`.curbs` (steps 3-4).
Their public names are importable from here too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon, box

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.centrelines import QUAD_SEGS, Street
from csboundary.data.synth.config import SynthConfig, rng_share
from csboundary.data.synth.curbs import (
    boulevard_medians,
    bulb_islands,
    round_convex_corners,
    roundabout_rings,
    traffic_islands,
)
from csboundary.data.synth.highways import with_highways
from csboundary.data.synth.layout import build_streets
from csboundary.data.synth.suburbs import local_streets

__all__ = [
    "QUAD_SEGS",
    "Block",
    "Street",
    "StreetNetwork",
    "boundary_lines",
    "build_network",
    "build_streets",
    "local_streets",
    "rng_share",
    "round_convex_corners",
    "with_highways",
]


@dataclass
class Block:
    """A block of land between streets, after rounding its corners with ``radius`` (0 = sharp)."""

    polygon: Polygon
    radius: float


@dataclass
class StreetNetwork:
    width: float  # city extent, metres
    height: float
    streets: list[Street]
    blocks: list[Block]
    islands: list[Polygon]
    medians: list[Polygon]
    roadway: object  # (Multi)Polygon, over the whole domain (city + margin)
    boundaries: list[tuple[LineString, str]] = field(default_factory=list)  # (line, kind), city extent


def build_network(cfg: SynthConfig, rng: np.random.Generator, width: float, height: float) -> StreetNetwork:
    """Streets -> roadway -> rounded blocks -> islands and medians -> ground-truth boundaries."""
    streets = build_streets(cfg, rng, width, height)
    road_by_street = [s.roadway() for s in streets]
    rings = roundabout_rings(cfg, rng, streets) if cfg.roundabout_share > 0 else []
    raw_roadway = shapely.union_all(road_by_street + [disc for disc, _ in rings])
    m = cfg.margin
    domain = box(-m, -m, width + m, height + m)
    land = domain.difference(raw_roadway)

    blocks: list[Block] = []
    for polygon in getattr(land, "geoms", [land]):
        if polygon.geom_type != "Polygon" or polygon.area < 30.0:
            continue
        radius = 0.0 if rng.random() < cfg.sharp_block_share else rng.uniform(*cfg.curb_radius)
        blocks.extend(Block(p, radius) for p in round_convex_corners(polygon, radius))

    roadway = domain.difference(shapely.union_all([b.polygon for b in blocks]))
    islands = traffic_islands(cfg, rng, streets, roadway)
    if rings or cfg.bulb_island_share > 0:
        extra = [island for _, island in rings] + bulb_islands(cfg, rng, streets)
        islands = [i for i in islands if not any(i.intersects(e.buffer(3.0)) for e in extra)] + extra
    medians = boulevard_medians(streets, road_by_street, roadway, [disc for disc, _ in rings])
    if islands or medians:
        roadway = roadway.difference(shapely.union_all(islands + medians))

    network = StreetNetwork(width, height, streets, blocks, islands, medians, roadway)
    network.boundaries = boundary_lines(roadway, islands, medians, width, height)
    return network


def boundary_lines(
    roadway, islands: list[Polygon], medians: list[Polygon], width: float, height: float
) -> list[tuple[LineString, str]]:
    """The roadway's rings clipped to the city, merged into LineStrings, each with its kind."""
    rings = []
    for polygon in getattr(roadway, "geoms", [roadway]):
        rings.append(polygon.exterior)
        rings.extend(polygon.interiors)
    lines = shapely.clip_by_rect(np.array([LineString(r.coords) for r in rings], dtype=object), 0.0, 0.0, width, height)
    merged = as_linestrings(shapely.line_merge(shapely.union_all([g for g in lines if not g.is_empty])))
    island_edges = shapely.union_all([p.exterior for p in islands]) if islands else None
    median_edges = shapely.union_all([p.exterior for p in medians]) if medians else None
    out = []
    for line in merged:
        probe = line.interpolate(0.5, normalized=True)
        if island_edges is not None and probe.distance(island_edges) < 1e-6:
            kind = "island"
        elif median_edges is not None and probe.distance(median_edges) < 1e-6:
            kind = "median"
        else:
            kind = "curb"
        out.append((line, kind))
    return out
