"""What lies on the roadway itself: lane lines, crosswalks and stop lines, bus and bike lanes,
and road wear (patches, seams, cracks, manholes). Painted before the blocks, so the curbs clip
whatever runs over them; none of it is a road boundary.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString
from shapely.ops import substring

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.config import SynthConfig, rng_share
from csboundary.data.synth.materials import WHITE_PAINT, YELLOW_PAINT, jitter_colour, scaled_colour
from csboundary.data.synth.objects import Painted, Scene
from csboundary.data.synth.shapes import centred_rect, rect


def add_road_markings(cfg: SynthConfig, rng: np.random.Generator, scene: Scene) -> None:
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
            scene.markings.append(Painted(line.buffer(width / 2, cap_style="flat"), jitter_colour(rng, colour, 0.1), 5))
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
        scene.markings.append(Painted(rect(p0 + across * s, along, across, 3.0, stripe), WHITE_PAINT, 3))
    stop = p0 + along * 4.0 - across * half
    scene.markings.append(Painted(rect(stop, along, across, 0.45, width), WHITE_PAINT, 3))


def add_road_wear(cfg: SynthConfig, rng: np.random.Generator, scene: Scene) -> None:
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
                patch = centred_rect(p + n * off, d, rng.uniform(2.0, 25.0), rng.uniform(1.0, max(1.2, s.width / 2)))
                scene.markings.append(
                    Painted(patch, scaled_colour(road, rng.uniform(0.7, 1.3)), int(rng.integers(3, 8)))
                )
            elif u < 0.8:  # a crack or tar seam: a thin dark wandering line
                pts = [p + n * off]
                heading = d * rng.choice([-1, 1]) if rng.random() < 0.6 else n
                for _ in range(int(rng.integers(3, 12))):
                    heading = heading + rng.normal(0, 0.35, 2)
                    heading /= np.linalg.norm(heading)
                    pts.append(pts[-1] + heading * rng.uniform(0.8, 3.0))
                seam = LineString(pts).buffer(rng.uniform(0.03, 0.08), cap_style="flat")
                scene.markings.append(Painted(seam, scaled_colour(road, rng.uniform(0.65, 0.85)), 2))
            elif u < 0.9:  # a long seam between paving passes
                seam = centred_rect(p + n * off, d, rng.uniform(15.0, 60.0), rng.uniform(0.1, 0.25))
                scene.markings.append(Painted(seam, scaled_colour(road, rng.uniform(0.45, 0.7)), 2))
            else:  # a manhole cover
                scene.markings.append(
                    Painted(
                        shapely.Point(p + n * off).buffer(0.35, quad_segs=4),
                        scaled_colour(road, rng.uniform(0.5, 0.8)),
                        3,
                    )
                )
