"""Suburban side streets (layout ``suburb``): curvy branches off a parent street ending in a dead
end or cul-de-sac, and crescents that return to it, each kept clear of every other street.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon

from csboundary.data.synth.centrelines import Street, unit_vector
from csboundary.data.synth.config import SynthConfig


def local_streets(
    cfg: SynthConfig, rng: np.random.Generator, parents: list[Street], existing: list[Street]
) -> list[Street]:
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
        p = p + 5 * unit_vector(angle)
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
