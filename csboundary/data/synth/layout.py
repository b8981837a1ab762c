"""Where the streets run (recipe step 1 of :mod:`.streets`): a grid of avenues and cross streets,
some curved, dropped or cut to dead ends, a few diagonals; then motorways (:mod:`.highways`) and,
for the suburb layout, curvy side streets (:mod:`.suburbs`); all clipped to the domain.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import LineString, box
from shapely.ops import substring

from csboundary.data.ground_truth import as_linestrings
from csboundary.data.synth.centrelines import Street, offset_line, unit_vector
from csboundary.data.synth.config import SynthConfig, rng_share
from csboundary.data.synth.highways import with_highways
from csboundary.data.synth.suburbs import local_streets


def _spaced_offsets(rng: np.random.Generator, half: float, spacing: tuple[float, float]) -> list[float]:
    """Offsets from -half to +half with gaps drawn from ``spacing``, starting at a random phase."""
    out, s = [], -half + rng.uniform(0, spacing[1])
    while s < half:
        out.append(s)
        s += rng.uniform(*spacing)
    return out


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
    along, across = unit_vector(bearing), unit_vector(bearing + math.pi / 2)

    streets: list[Street] = []
    avenues: list[LineString] = []
    for offset in _spaced_offsets(rng, half, cfg.avenue_spacing):
        bend = (
            _bend(rng, cfg.curve_amplitude, 0.22 * cfg.avenue_spacing[0])
            if rng_share(rng, cfg.avenue_curve_share)
            else None
        )
        line = offset_line(centre, along, across, offset, half, bend)
        w = rng.uniform(*cfg.avenue_width)
        if rng.random() < cfg.boulevard_share:
            streets.append(
                Street(
                    line,
                    w + rng.uniform(*cfg.boulevard_extra_width),
                    "boulevard",
                    median=rng.uniform(*cfg.median_width),
                )
            )
        else:
            streets.append(Street(line, w, "avenue"))
        avenues.append(line)

    offsets = _spaced_offsets(rng, half, cfg.street_spacing)
    for i, offset in enumerate(offsets):
        skew = math.radians(rng.uniform(-cfg.cross_street_skew_deg, cfg.cross_street_skew_deg))
        direction = unit_vector(bearing + math.pi / 2 + skew)
        normal = unit_vector(bearing + skew)
        gap = (
            min(abs(offset - offsets[j]) for j in (i - 1, i + 1) if 0 <= j < len(offsets))
            if len(offsets) > 1
            else 100.0
        )
        bend, kind = None, "street"
        if rng.random() < cfg.curved_street_share:
            bend, kind = _bend(rng, cfg.curve_amplitude, 0.22 * gap), "curved"
        line = offset_line(centre, direction, normal, offset, half, bend)
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
        line = offset_line(
            through,
            unit_vector(angle),
            unit_vector(angle + math.pi / 2),
            0.0,
            half + np.linalg.norm(through - centre),
            bend,
        )
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
            clipped.append(
                Street(
                    part,
                    s.width,
                    s.kind,
                    s.median,
                    s.bulb_radius if part.coords[-1] == s.centreline.coords[-1] else 0.0,
                )
            )
    return clipped
