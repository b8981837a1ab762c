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

_STEPS = ((0, 1, 1.0), (1, 0, 1.0), (1, 1, np.sqrt(2.0)), (1, -1, np.sqrt(2.0)))


def skeleton_pixel_links(skeleton: np.ndarray, corner_diagonals: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 2) pixel (row, col) of the skeleton's pixels in raster order, (E, 2) node pairs of
    8-neighbours (each pair once), and (E,) their distances in px."""
    mask = np.asarray(skeleton, dtype=bool)
    rows, cols = np.nonzero(mask)
    h, w = mask.shape
    ids = np.full((h + 2, w + 2), -1, dtype=np.int64)
    ids[rows + 1, cols + 1] = np.arange(len(rows))
    on = ids >= 0
    centre = ids[1 : h + 1, 1 : w + 1]
    pairs, lengths = [], []
    for dr, dc, length in _STEPS:
        other = ids[1 + dr : h + 1 + dr, 1 + dc : w + 1 + dc]
        link = (centre >= 0) & (other >= 0)
        if dr and dc and not corner_diagonals:
            link &= ~(on[1 : h + 1, 1 + dc : w + 1 + dc] | on[1 + dr : h + 1 + dr, 1 : w + 1])
        pairs.append(np.stack([centre[link], other[link]], axis=1))
        lengths.append(np.full(int(link.sum()), length))
    return np.stack([rows, cols], axis=1), np.concatenate(pairs).reshape(-1, 2), np.concatenate(lengths)


def skeleton_distance_graph(skeleton: np.ndarray) -> tuple[np.ndarray, sparse.csr_matrix]:
    """The skeleton's pixels (as :func:`skeleton_pixel_links`) and the (N, N) sparse matrix of
    their link lengths, for ``scipy.sparse.csgraph`` (undirected, each link stored once)."""
    pixels, pairs, lengths = skeleton_pixel_links(skeleton)
    n = len(pixels)
    return pixels, sparse.csr_matrix((lengths, (pairs[:, 0], pairs[:, 1])), shape=(n, n))
