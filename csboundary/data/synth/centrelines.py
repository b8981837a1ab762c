"""What a street is before the roadway exists: a centreline, its curb-to-curb width and the
polygon it paves, and the straight or bent lines the layouts draw centrelines on.

Shared by every layout (:mod:`.layout`, :mod:`.highways`, :mod:`.suburbs`) and by the curb
shapes (:mod:`.curbs`), so it imports none of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString, Point, Polygon

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


def unit_vector(angle: float) -> np.ndarray:
    """The unit vector at ``angle`` radians from the x axis (east), counter-clockwise."""
    return np.array([math.cos(angle), math.sin(angle)])


def offset_line(
    centre: np.ndarray, along: np.ndarray, across: np.ndarray, offset: float, half: float, bend=None
) -> LineString:
    """A line through ``centre + across*offset`` in direction ``along``; ``bend(t)`` shifts it sideways."""
    t = np.arange(-half, half + 5.0, 5.0) if bend is not None else np.array([-half, half])
    shift = bend(t) if bend is not None else 0.0
    pts = centre + np.outer(t, along) + np.outer(offset + shift, across)
    return LineString(pts)
