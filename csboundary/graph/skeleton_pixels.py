"""The graph of a one-pixel-wide skeleton's pixels: the one place where skeleton pixels become
nodes, used by vertex extraction (geodesic runs of keypoint pieces) and by the skeleton graph
(chains of a boundary mask).

Nodes are the skeleton's pixels in raster order; links join 8-neighbours, with lengths 1
(orthogonal) and sqrt(2) (diagonal). A diagonal link beside which an orthogonal two-step path
exists can be left out (``corner_diagonals=False``): for chain decomposition, where it would make
every corner of a thin line a little triangle (a false junction); geodesic distances keep it,
since the diagonal is the shorter way.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from csboundary.graph.pixel_index import nonzero_pixels

_STEPS = ((0, 1, 1.0), (1, 0, 1.0), (1, 1, np.sqrt(2.0)), (1, -1, np.sqrt(2.0)))


def skeleton_pixel_links(
    skeleton: np.ndarray, corner_diagonals: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 2) pixel (row, col) of the skeleton's pixels in raster order, (E, 2) node pairs of
    8-neighbours (each pair once, grouped by step and in raster order of the first pixel), and
    (E,) their distances in px. Works on the pixel list (a binary search per neighbour), so the
    cost follows the skeleton's size, not the map's."""
    mask = np.asarray(skeleton, dtype=bool)
    rows, cols = nonzero_pixels(mask)
    pixels = np.stack([rows, cols], axis=1)
    if len(rows) == 0:
        return pixels, np.zeros((0, 2), np.int64), np.zeros(0)
    h, w = mask.shape
    flat = rows * w + cols  # increasing: the pixels come in raster order

    def node_at(r: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Node of pixel (r, c), -1 where it is off the map or not a skeleton pixel."""
        key = np.where((r >= 0) & (r < h) & (c >= 0) & (c < w), r * w + c, -1)
        at = np.minimum(np.searchsorted(flat, key), len(flat) - 1)
        return np.where(flat[at] == key, at, -1)

    pairs, lengths = [], []
    for dr, dc, length in _STEPS:
        other = node_at(rows + dr, cols + dc)
        link = other >= 0
        if dr and dc and not corner_diagonals:
            link &= (node_at(rows, cols + dc) < 0) & (node_at(rows + dr, cols) < 0)
        pairs.append(np.stack([np.flatnonzero(link), other[link]], axis=1))
        lengths.append(np.full(int(link.sum()), length))
    return pixels, np.concatenate(pairs).astype(np.int64), np.concatenate(lengths)


def skeleton_distance_graph(skeleton: np.ndarray) -> tuple[np.ndarray, sparse.csr_matrix]:
    """The skeleton's pixels (as :func:`skeleton_pixel_links`) and the (N, N) sparse matrix of
    their link lengths, for ``scipy.sparse.csgraph`` (undirected, each link stored once)."""
    pixels, pairs, lengths = skeleton_pixel_links(skeleton)
    n = len(pixels)
    return pixels, sparse.csr_matrix((lengths, (pairs[:, 0], pairs[:, 1])), shape=(n, n))
