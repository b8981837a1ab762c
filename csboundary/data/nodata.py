"""What the FPN sees where a window has no imagery (beyond the mosaic's edge, nodata holes).

Zeros there draw a sharp edge along the imagery's border, and the network, which never learnt
that such an edge is not a curb, traces it as a boundary and loses real ones near it (on the
707 px real crops placed in 1100 px windows the border became most of the predicted length).
Filling each missing pixel with its nearest valid pixel leaves no edge to trace; the maps are
still zeroed outside the imagery afterwards, so nothing is predicted where nothing was seen.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def fill_nodata(data: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(bands, h, w) ``data`` with every pixel where ``valid`` (h, w) is False replaced by the
    nearest valid pixel (Euclidean; ties as ``scipy.ndimage.distance_transform_edt`` breaks
    them). Returned as is when every pixel or none is valid."""
    valid = np.asarray(valid, bool)
    if valid.all() or not valid.any():
        return data
    rows, cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    if valid[r0:r1, c0:c1].all():  # a window reaching beyond the mosaic: repeating the edge is the same fill, 20x cheaper
        h, w = valid.shape
        return np.pad(data[:, r0:r1, c0:c1], ((0, 0), (r0, h - r1), (c0, w - c1)), mode="edge")
    rows, cols = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return np.ascontiguousarray(data[:, rows, cols])
