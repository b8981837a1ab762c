"""Rectangles placed by a corner or a centre and a direction: the shape of cars, houses, pools,
stalls and paint stripes, shared by every module that places them.
"""

from __future__ import annotations

import numpy as np
from shapely.geometry import Polygon


def rect(origin: np.ndarray, along: np.ndarray, across: np.ndarray, length: float, width: float) -> Polygon:
    """Rectangle spanning ``origin + along*[0, length] + across*[0, width]``."""
    return Polygon([origin, origin + along * length, origin + along * length + across * width, origin + across * width])


def centred_rect(centre: np.ndarray, along: np.ndarray, length: float, width: float) -> Polygon:
    """Rectangle centred on ``centre``, ``length`` along the unit ``along`` and ``width`` across it."""
    across = np.array([-along[1], along[0]])
    return rect(centre - along * length / 2 - across * width / 2, along, across, length, width)
