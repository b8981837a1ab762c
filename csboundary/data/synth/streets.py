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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon, box
from shapely.ops import substring

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.config import SynthConfig

QUAD_SEGS = 16  # arc resolution: a 12 m curb return deviates < 0.1 px from a true circle


@dataclass
class Street:
    """A centreline with its curb-to-curb width; ``median`` > 0 for boulevards."""

    centreline: LineString
    width: float
    kind: str  # avenue | boulevard | street | curved | diagonal | dead_end | local | highway | ramp
    median: float = 0.0
    bulb_radius: float = 0.0  # cul-de-sac bulb at the centreline's end

    def roadway(self) -> Polygon:
        shape = self.centreline.buffer(self.width / 2, cap_style="flat", join_style="round", quad_segs=QUAD_SEGS)
        if self.bulb_radius > 0:
            end = Point(self.centreline.coords[-1])
            shape = shape.union(end.buffer(self.bulb_radius, quad_segs=QUAD_SEGS))
        return shape


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


def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def _spaced_offsets(rng: np.random.Generator, half: float, spacing: tuple[float, float]) -> list[float]:
    """Offsets from -half to +half with gaps drawn from ``spacing``, starting at a random phase."""
    out, s = [], -half + rng.uniform(0, spacing[1])
    while s < half:
        out.append(s)
        s += rng.uniform(*spacing)
    return out


def _line(centre: np.ndarray, along: np.ndarray, across: np.ndarray, offset: float, half: float, bend=None) -> LineString:
    """A line through ``centre + across*offset`` in direction ``along``; ``bend(t)`` shifts it sideways."""
    t = np.arange(-half, half + 5.0, 5.0) if bend is not None else np.array([-half, half])
    shift = bend(t) if bend is not None else 0.0
    pts = centre + np.outer(t, along) + np.outer(offset + shift, across)
    return LineString(pts)


def rng_share(rng: np.random.Generator, share: float) -> bool:
    """True with probability ``share``; draws nothing when ``share`` is 0, so a switched-off
    style knob leaves the random stream (and hence the city) unchanged."""
    return share > 0 and rng.random() < share


def _bend(rng: np.random.Generator, amplitude: tuple[float, float], cap: float):
    """A sideways sine shift ``bend(t)`` of amplitude drawn from ``amplitude`` (at most ``cap``)."""
    amp = min(rng.uniform(*amplitude), cap)
    wavelength, phase = rng.uniform(250, 500), rng.uniform(0, 2 * math.pi)
    return lambda t: amp * np.sin(2 * math.pi * t / wavelength + phase)


def _split_between(line: LineString, cutters: list[LineString]) -> list[LineString]:
    """Pieces of ``line`` between consecutive crossings with ``cutters`` (ends included)."""
    cuts = {0.0, line.length}
    for cutter in cutters:
        hit = line.intersection(cutter)
        for part in getattr(hit, "geoms", [hit]):
            if not part.is_empty and part.geom_type == "Point":
                cuts.add(line.project(part))
    ordered = sorted(cuts)
    return [substring(line, a, b) for a, b in zip(ordered, ordered[1:]) if b - a > 1.0]


def build_streets(cfg: SynthConfig, rng: np.random.Generator, width: float, height: float) -> list[Street]:
    """Centrelines of avenues, cross streets (some curved, dropped or dead-ended) and diagonals."""
    m = cfg.margin
    centre = np.array([width / 2, height / 2])
    half = math.hypot(width + 2 * m, height + 2 * m) / 2 + 40.0
    bearing = rng.uniform(math.radians(cfg.bearing_deg[0]), math.radians(cfg.bearing_deg[1]))
    along, across = _unit(bearing), _unit(bearing + math.pi / 2)

    streets: list[Street] = []
    avenues: list[LineString] = []
    for offset in _spaced_offsets(rng, half, cfg.avenue_spacing):
        bend = _bend(rng, cfg.curve_amplitude, 0.22 * cfg.avenue_spacing[0]) if rng_share(rng, cfg.avenue_curve_share) else None
        line = _line(centre, along, across, offset, half, bend)
        w = rng.uniform(*cfg.avenue_width)
        if rng.random() < cfg.boulevard_share:
            streets.append(Street(line, w + rng.uniform(*cfg.boulevard_extra_width), "boulevard", median=rng.uniform(*cfg.median_width)))
        else:
            streets.append(Street(line, w, "avenue"))
        avenues.append(line)

    offsets = _spaced_offsets(rng, half, cfg.street_spacing)
    for i, offset in enumerate(offsets):
        skew = math.radians(rng.uniform(-cfg.cross_street_skew_deg, cfg.cross_street_skew_deg))
        direction = _unit(bearing + math.pi / 2 + skew)
        normal = _unit(bearing + skew)
        gap = min(abs(offset - offsets[j]) for j in (i - 1, i + 1) if 0 <= j < len(offsets)) if len(offsets) > 1 else 100.0
        bend, kind = None, "street"
        if rng.random() < cfg.curved_street_share:
            bend, kind = _bend(rng, cfg.curve_amplitude, 0.22 * gap), "curved"
        line = _line(centre, direction, normal, offset, half, bend)
        w = rng.uniform(*cfg.street_width)
        for piece in _split_between(line, avenues):
            u = rng.random()
            if u < cfg.dropped_segment_share:
                continue
            if u < cfg.dropped_segment_share + cfg.dead_end_share and piece.length > 40:
                length = piece.length * rng.uniform(0.35, 0.6)
                if rng.random() < 0.5:  # the dead end is the stub's last point
                    stub = substring(piece, 0, length)
                else:
                    stub = shapely.reverse(substring(piece, piece.length - length, piece.length))
                bulb = w * rng.uniform(0.75, 0.95) if rng.random() < cfg.cul_de_sac_share else 0.0
                streets.append(Street(stub, w, "dead_end", bulb_radius=bulb))
            else:
                streets.append(Street(piece, w, kind))

    area_km2 = (width + 2 * m) * (height + 2 * m) / 1e6
    for _ in range(rng.poisson(cfg.diagonals_per_km2 * area_km2)):
        angle = bearing + rng.choice([-1, 1]) * math.radians(rng.uniform(25, 65))
        through = np.array([rng.uniform(0.2, 0.8) * width, rng.uniform(0.2, 0.8) * height])
        bend = None
        if rng.random() < 0.5:
            amp, wl = rng.uniform(15, 40), rng.uniform(700, 1400)
            bend = lambda t, a=amp, wl=wl: a * np.sin(2 * math.pi * t / wl)  # noqa: E731
        line = _line(through, _unit(angle), _unit(angle + math.pi / 2), 0.0, half + np.linalg.norm(through - centre), bend)
        streets.append(Street(line, rng.uniform(*cfg.street_width) + 1.0, "diagonal"))

    if cfg.highways > 0:
        streets = with_highways(cfg, rng, streets, centre, half, bearing)

    if cfg.layout == "suburb":
        first = local_streets(cfg, rng, streets, streets)
        streets.extend(first + local_streets(cfg, rng, first, streets + first))  # side streets of side streets
    elif cfg.layout != "grid":
        raise ValueError(f"layout must be grid or suburb, got {cfg.layout!r}")

    domain = box(-m - 20, -m - 20, width + m + 20, height + m + 20)
    clipped = []
    for s in streets:
        line = s.centreline.intersection(domain)
        for part in as_linestrings(line):
            clipped.append(Street(part, s.width, s.kind, s.median, s.bulb_radius if part.coords[-1] == s.centreline.coords[-1] else 0.0))
    return clipped


def with_highways(cfg: SynthConfig, rng: np.random.Generator, streets: list[Street], centre: np.ndarray, half: float,
                  bearing: float) -> list[Street]:
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
        line = _line(through, _unit(angle), _unit(angle + math.pi / 2), 0.0, half + float(np.linalg.norm(through - centre)), bend)
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
                    kept.append(Street(part, street.width, street.kind, street.median, street.bulb_radius if part.coords[-1] == end else 0.0))
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


def _diamond_ramps(cfg: SynthConfig, rng: np.random.Generator, highway: LineString, avenue: Street, crossing: Point,
                   width: float) -> list[Street]:
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
            sine = max(abs(float(outward @ n)), 0.3)  # the avenue may cross obliquely: reach the same distance from the highway
            p2 = x + (width / 2 + out) / sine * outward
            t = np.linspace(0.0, 1.0, 32)[:, None]
            curve = (1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t**2 * p2
            ramps.append(Street(LineString(curve), ramp_width, "ramp"))
    return ramps


def local_streets(cfg: SynthConfig, rng: np.random.Generator, parents: list[Street], existing: list[Street]) -> list[Street]:
    """Suburban local streets: curvy branches leaving a parent street at a T-junction and ending
    in a dead end or cul-de-sac bulb, and crescents that come back to the same parent.

    A candidate is kept only if it stays ``clearance`` metres from every other street, so the
    blocks between them hold a row of houses on each side.
    """
    clearance = 28.0
    kept: list[Polygon] = []  # clearance zones of accepted local streets
    out: list[Street] = []
    for parent in parents:
        foreign = [s.centreline for s in existing if s is not parent]
        zone = shapely.union_all([line.buffer(clearance) for line in foreign]) if foreign else Polygon()
        shapely.prepare(zone)
        t = rng.uniform(*cfg.branch_spacing) / 2
        while t < parent.centreline.length - 20:
            p = np.array(parent.centreline.interpolate(t).coords[0])
            q = np.array(parent.centreline.interpolate(min(t + 2.0, parent.centreline.length)).coords[0])
            d = (q - p) / max(np.linalg.norm(q - p), 1e-9)
            side = 1.0 if rng.random() < 0.5 else -1.0
            normal = np.array([-d[1], d[0]]) * side
            w = rng.uniform(*cfg.street_width)
            span = rng.uniform(60, 120)
            if rng.random() < cfg.loop_share and t + span < parent.centreline.length - 20:
                end = np.array(parent.centreline.interpolate(t + span).coords[0])
                line, bulb = _crescent(p, end, normal, rng.uniform(*cfg.branch_length) * 0.6), 0.0
            else:
                line = _curvy_branch(rng, p, normal, rng.uniform(*cfg.branch_length))
                bulb = w * rng.uniform(0.8, 1.1) if rng.random() < cfg.cul_de_sac_share else 0.0
            t += rng.uniform(*cfg.branch_spacing)
            away = line.difference(Point(p).buffer(parent.width / 2 + 2.0))
            body = away.buffer(w / 2 + 2.0 + bulb)
            if zone.intersects(away) or (kept and shapely.intersects(np.array(kept, dtype=object), body).any()):
                continue
            kept.append(line.buffer(clearance * 0.6 + bulb))
            out.append(Street(line, w, "local", bulb_radius=bulb))
    return out


def _curvy_branch(rng: np.random.Generator, start: np.ndarray, heading: np.ndarray, length: float) -> LineString:
    """A street leaving ``start`` along ``heading`` and turning gently (up to ~60 degrees)."""
    turn = math.radians(rng.uniform(-60, 60)) / max(length, 1.0)  # curvature, radians per metre
    angle = math.atan2(heading[1], heading[0])
    points, p = [start.copy()], start.copy()
    for _ in range(int(length // 5)):
        angle += turn * 5
        p = p + 5 * _unit(angle)
        points.append(p)
    return LineString(points)


def _crescent(start: np.ndarray, end: np.ndarray, normal: np.ndarray, depth: float) -> LineString:
    """A U-shaped street from ``start`` into the block, ``depth`` deep, and back out at ``end``.
    The bulge is computed with ``math`` (the C library), not NumPy: NumPy's power rounds the
    last bit differently on CPUs with AVX-512, and a side street that starts on the crescent
    then crosses another street on one machine and not the other, giving a different city."""
    s = np.linspace(0, math.pi, 40)
    bulge = np.array([math.sin(v) ** 0.6 for v in s])
    pts = start + np.outer((1 - np.cos(s)) / 2, end - start) + np.outer(bulge * depth, normal)
    return LineString(pts)


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


def _roundabouts(cfg: SynthConfig, rng: np.random.Generator, streets: list[Street]) -> list[tuple[Polygon, Polygon]]:
    """(ring disc, central island) at a share of crossings; rings never overlap one another."""
    out: list[tuple[Polygon, Polygon]] = []
    for hit, i, j in _crossings(streets, 6.0):
        if rng.random() >= cfg.roundabout_share:
            continue
        outer = rng.uniform(*cfg.roundabout_radius)
        inner = outer - rng.uniform(6.0, 8.0)
        if inner < 3.0 or any(hit.distance(o.centroid) < outer + o_r + 30 for o, o_r in ((d, math.sqrt(d.area / math.pi)) for d, _ in out)):
            continue
        out.append((hit.buffer(outer, quad_segs=QUAD_SEGS), hit.buffer(inner, quad_segs=QUAD_SEGS)))
    return out


def _bulb_islands(cfg: SynthConfig, rng: np.random.Generator, streets: list[Street]) -> list[Polygon]:
    """Planted centre islands in a share of the cul-de-sac bulbs of radius 8 m or more."""
    out = []
    for s in streets:
        if s.bulb_radius >= 8.0 and rng_share(rng, cfg.bulb_island_share):
            out.append(Point(s.centreline.coords[-1]).buffer(s.bulb_radius - rng.uniform(5.5, 6.5), quad_segs=QUAD_SEGS))
    return [p for p in out if p.area > math.pi * 2.0**2]


def round_convex_corners(polygon: Polygon, radius: float) -> list[Polygon]:
    """Morphological opening: rounds convex corners to ``radius``, keeps concave corners sharp."""
    if radius <= 0:
        return [polygon]
    opened = polygon.buffer(-radius, quad_segs=QUAD_SEGS).buffer(radius, quad_segs=QUAD_SEGS)
    return [p for p in getattr(opened, "geoms", [opened]) if p.geom_type == "Polygon" and p.area > 30.0]


def _islands(cfg: SynthConfig, rng: np.random.Generator, streets: list[Street], roadway) -> list[Polygon]:
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
            corners = [(hit.x + side * 0.58 * math.cos(theta + k * 2 * math.pi / 3), hit.y + side * 0.58 * math.sin(theta + k * 2 * math.pi / 3)) for k in range(3)]
            island = Polygon(corners).buffer(0.8, quad_segs=QUAD_SEGS)
            if inside.contains(island) and not any(island.distance(o) < 3.0 for o in islands):
                islands.append(island)
    return islands


def _medians(streets: list[Street], road_by_street: list[Polygon], roadway, avoid: list[Polygon] = ()) -> list[Polygon]:
    """Boulevard medians, interrupted at every crossing street and roundabout (``avoid``), with rounded noses."""
    medians: list[Polygon] = []
    tree = shapely.STRtree(road_by_street)
    inside = roadway.buffer(-1.0)
    shapely.prepare(inside)
    for i, s in enumerate(streets):
        if s.median <= 0:
            continue
        strip = s.centreline.buffer(s.median / 2, cap_style="flat")
        if s.kind == "highway":  # crossed by few streets: its pieces must not run out of the domain (they would fail `inside`)
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


def build_network(cfg: SynthConfig, rng: np.random.Generator, width: float, height: float) -> StreetNetwork:
    """Streets -> roadway -> rounded blocks -> islands and medians -> ground-truth boundaries."""
    streets = build_streets(cfg, rng, width, height)
    road_by_street = [s.roadway() for s in streets]
    rings = _roundabouts(cfg, rng, streets) if cfg.roundabout_share > 0 else []
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
    islands = _islands(cfg, rng, streets, roadway)
    if rings or cfg.bulb_island_share > 0:
        extra = [island for _, island in rings] + _bulb_islands(cfg, rng, streets)
        islands = [i for i in islands if not any(i.intersects(e.buffer(3.0)) for e in extra)] + extra
    medians = _medians(streets, road_by_street, roadway, [disc for disc, _ in rings])
    if islands or medians:
        roadway = roadway.difference(shapely.union_all(islands + medians))

    network = StreetNetwork(width, height, streets, blocks, islands, medians, roadway)
    network.boundaries = boundary_lines(roadway, islands, medians, width, height)
    return network


def boundary_lines(roadway, islands: list[Polygon], medians: list[Polygon], width: float, height: float) -> list[tuple[LineString, str]]:
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
