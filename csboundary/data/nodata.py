"""What the FPN sees where a window has no imagery (beyond the mosaic's edge, nodata holes).

Zeros there draw a sharp edge along the imagery's border, and the network, which never learnt
that such an edge is not a curb, traces it as a boundary and loses real ones near it (on the
707 px real crops placed in 1100 px windows the border became most of the predicted length).
Repeating the nearest valid pixel (used until 2026-12-03) leaves no step, but draws streaks
perpendicular to the border, and the network traced the seam between texture and streaks: a
ring of false boundary a few pixels inside every crop. Mirroring the imagery across its border
continues its texture instead (F1@5 on the 14 Ottawa crops 0.349 -> 0.466, docs/real-imagery.md).
The maps are still zeroed outside the imagery afterwards, so nothing is predicted where nothing
was seen.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def fill_nodata(data: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(bands, h, w) ``data`` with every pixel where ``valid`` (h, w) is False filled with the
    imagery mirrored across its border: a missing pixel p whose nearest valid pixel is b (Euclidean,
    ties as ``scipy.ndimage.distance_transform_edt`` breaks them) takes the value at 2b - p (clipped to the
    window), or, where that is missing too, the value of the valid pixel nearest to it.

    A rectangle of imagery wider than what is missing on each side (a window reaching beyond the
    mosaic) is the same rule as NumPy's ``reflect`` padding, which is used there (20x cheaper).
    Returned as is when every pixel or none is valid."""
    valid = np.asarray(valid, bool)
    if valid.all() or not valid.any():
        return data
    rows, cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    h, w = valid.shape
    if valid[r0:r1, c0:c1].all() and max(r0, h - r1) < r1 - r0 and max(c0, w - c1) < c1 - c0:
        return np.pad(data[:, r0:r1, c0:c1], ((0, 0), (r0, h - r1), (c0, w - c1)), mode="reflect")
    return mirror_fill(data, valid)


def mirror_fill(data: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """:func:`fill_nodata`'s rule on any ``valid`` mask with at least one valid pixel, without
    the rectangle shortcut."""
    h, w = valid.shape
    near_r, near_c = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    grid_r, grid_c = np.indices(valid.shape)
    mirror_r = np.clip(2 * near_r - grid_r, 0, h - 1)
    mirror_c = np.clip(2 * near_c - grid_c, 0, w - 1)
    # the mirrored pixel where it is valid, else the valid pixel nearest to it
    src_r, src_c = near_r[mirror_r, mirror_c], near_c[mirror_r, mirror_c]
    return np.ascontiguousarray(data[:, src_r, src_c])
