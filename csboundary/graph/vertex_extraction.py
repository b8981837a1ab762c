"""Graph vertices from a keypoint probability map (paper Section IV-C, "Vertex extraction").

The keypoint map is Gaussian heat (sigma 3 px) around isolated keypoints and along gathered runs
(rounded corners). Thresholding it gives one blob per keypoint or run; the blob's skeleton tells
the two apart by length. A short skeleton is one keypoint: its vertex is the blob's centre. A long
skeleton is a gathered run: only its two ends become vertices, joined by a "corner" edge that
carries the skeleton as its polyline, so the adjacency network (AfANet) never has to predict the
inside of a rounded corner.

Choices the paper leaves open:

* The centre of a short piece is the centroid of the blob's pixels weighted by ``p - threshold``
  rather than the middle of its skeleton: the skeleton lives on pixel centres (and thinning a 3x3
  block leaves two off-centre pixels), while the weighted centroid is sub-pixel and, with weights
  that vanish at the blob's rim, barely biased by how the rim falls on the pixel grid (about
  0.05 px mean error on a thresholded Gaussian at a random sub-pixel position).
* The run of a long piece is the skeleton's geodesic diameter (8-connected pixels, steps 1 and
  sqrt(2)), found by two Dijkstra sweeps: from any pixel to the farthest, then from there to the
  farthest. That is exact on trees (branched skeletons: the longest branch-to-branch path) and a
  good approximation on loops (a ring gives two nearly opposite points and half the ring).
* All pieces are processed at once: one sparse graph over every skeleton pixel of the map and one
  multi-source Dijkstra per sweep (pieces are disconnected, so each pixel's nearest source is its
  own piece's), so the cost grows with the skeleton size, not with the number of pieces: about
  0.1 s for a 1100x1100 map with 150 pieces. Thinning takes one pass per pixel of a blob's
  half-thickness, so a map that is above the threshold nearly everywhere (an untrained network)
  takes seconds; keypoint blobs are ~7 px thick.

Coordinates are continuous (col, row) in the map's own pixel frame; pixel [r, c] is centred at
(c + 0.5, r + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import csgraph
from skimage.morphology import skeletonize

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.pixel_index import nonzero_pixels
from csboundary.graph.skeleton_pixels import skeleton_distance_graph

ISOLATED = "isolated"  # vertex at the centre of a short piece (same names as csboundary.labels.keypoints)
CORNER = "corner"  # vertex at an end of a long piece; also the kind of the edge joining the two ends
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class VertexConfig:
    """Parameters of vertex extraction, in probability and pixel units.

    threshold: pixels with probability >= this are keypoint pixels. With sigma 3 px heat, 0.5 keeps
        a disc of radius ~3.5 px around a keypoint (a band ~7 px wide along a run).
    min_area_px: connected pieces (8-connected) with fewer pixels are noise and dropped.
    gather_min_length_px: a piece whose skeleton's longest path (geodesic, in px) is at least this
        long is a gathered run (two corner vertices and a corner edge); shorter ones are one
        isolated vertex. Same meaning and default as ``LabelConfig.gather_min_length_px``; a
        piece whose skeleton is a single pixel is always short.
    """

    threshold: float = 0.5
    min_area_px: int = 4
    gather_min_length_px: float = 12.0

    def __post_init__(self) -> None:
        if not np.isfinite(self.threshold):
            raise ValueError(f"threshold must be finite, got {self.threshold}")
        if self.min_area_px < 1:
            raise ValueError(f"min_area_px must be >= 1, got {self.min_area_px}")
        if not self.gather_min_length_px >= 0:
            raise ValueError(f"gather_min_length_px must be >= 0, got {self.gather_min_length_px}")


def extract_vertices(keypoint_prob: np.ndarray, config: VertexConfig = VertexConfig()) -> BoundaryGraph:
    """Vertices (and corner edges) of a (h, w) keypoint probability map; see the module docstring.

    Vertices come piece by piece (in raster order of each piece's first pixel): one "isolated"
    vertex for a short piece, two "corner" vertices (u, u + 1) for a long one, joined by a
    "corner" edge whose polyline runs through the skeleton's pixel centres from u to u + 1.
    """
    graph, _ = extract_vertices_with_scores(keypoint_prob, config)
    return graph


def extract_vertices_with_scores(
    keypoint_prob: np.ndarray, config: VertexConfig = VertexConfig()
) -> tuple[BoundaryGraph, np.ndarray]:
    """:func:`extract_vertices` plus (N,) scores: each vertex's highest probability in its piece.

    The graph's ``edge_scores`` hold, for each corner edge, the mean probability along its
    skeleton path. Raises ValueError if the map is not 2-D or holds NaN or infinite values.
    """
    prob = _checked(keypoint_prob)
    labels, n_pieces = _pieces(prob, config)
    if n_pieces == 0:
        return _empty(), np.zeros(0)
    centres, peak = _centres_and_peaks(prob, labels, n_pieces, config.threshold)
    paths = _longest_skeleton_paths(labels > 0, labels, n_pieces)

    vertices: list[np.ndarray] = []
    kinds: list[str] = []
    scores: list[float] = []
    edges: list[tuple[int, int]] = []
    polylines: list[np.ndarray] = []
    edge_scores: list[float] = []
    for k in range(n_pieces):
        path, length = paths[k]
        if path is not None and len(path) >= 2 and length >= config.gather_min_length_px:
            rows, cols = path[:, 0], path[:, 1]
            line = np.stack([cols + 0.5, rows + 0.5], axis=1)
            u = len(vertices)
            vertices += [line[0], line[-1]]
            kinds += [CORNER, CORNER]
            scores += [peak[k], peak[k]]
            edges.append((u, u + 1))
            polylines.append(line)
            edge_scores.append(float(prob[rows, cols].mean()))
        else:
            vertices.append(centres[k])
            kinds.append(ISOLATED)
            scores.append(peak[k])
    graph = BoundaryGraph(
        np.array(vertices, dtype=float).reshape(-1, 2),
        np.array(edges, dtype=np.int64).reshape(-1, 2),
        vertex_kinds=kinds,
        edge_kinds=[CORNER] * len(edges),
        edge_polylines=polylines,
        edge_scores=np.array(edge_scores, dtype=float),
    )
    return graph, np.array(scores, dtype=float)


# -- steps ------------------------------------------------------------------------------------------


def _checked(keypoint_prob: np.ndarray) -> np.ndarray:
    prob = np.asarray(keypoint_prob)
    if prob.ndim != 2:
        raise ValueError(f"keypoint_prob must be a 2-D (h, w) map, got shape {prob.shape}")
    if prob.dtype == bool or not np.issubdtype(prob.dtype, np.number) or np.iscomplexobj(prob):
        raise ValueError(f"keypoint_prob must hold real numbers, got dtype {prob.dtype}")
    prob = prob.astype(np.float64, copy=False)
    finite = np.isfinite(prob)
    if not finite.all():
        bad = np.argwhere(~finite)
        n_nan = int(np.isnan(prob).sum())
        r, c = bad[0]
        raise ValueError(
            f"keypoint_prob holds {n_nan} NaN and {len(bad) - n_nan} infinite value(s) "
            f"(first at row {r}, col {c}); a probability map must be finite"
        )
    return prob


def _pieces(prob: np.ndarray, config: VertexConfig) -> tuple[np.ndarray, int]:
    """8-connected pieces of ``prob >= threshold`` with at least ``min_area_px`` pixels, labelled 1..K."""
    if prob.size == 0:
        return np.zeros(prob.shape, np.int32), 0
    labels, n = ndimage.label(prob >= config.threshold, structure=_EIGHT)
    if n == 0:
        return labels, 0
    rows, cols = nonzero_pixels(labels)  # keypoint pixels are a few percent of the map: relabel only them
    piece = labels[rows, cols]
    keep = np.bincount(piece, minlength=n + 1) >= config.min_area_px
    keep[0] = False
    labels[rows, cols] = (np.cumsum(keep) * keep)[piece]
    return labels.astype(np.int32, copy=False), int(keep.sum())


def _centres_and_peaks(prob: np.ndarray, labels: np.ndarray, n: int, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Per piece: (n, 2) centroid (col, row) of its pixels weighted by ``p - threshold`` (plain
    centroid where every weight is 0, i.e. a plateau at exactly the threshold), and (n,) its
    highest probability."""
    rows, cols = nonzero_pixels(labels)
    lab = labels[rows, cols]
    p = prob[rows, cols]
    peak = np.full(n + 1, -np.inf)
    np.maximum.at(peak, lab, p)
    w = p - threshold
    x, y = cols + 0.5, rows + 0.5
    ws = np.bincount(lab, weights=w, minlength=n + 1)[1:]
    count = np.bincount(lab, minlength=n + 1)[1:].astype(float)
    wx = np.bincount(lab, weights=w * x, minlength=n + 1)[1:]
    wy = np.bincount(lab, weights=w * y, minlength=n + 1)[1:]
    ux = np.bincount(lab, weights=x, minlength=n + 1)[1:]
    uy = np.bincount(lab, weights=y, minlength=n + 1)[1:]
    ok = ws > 0
    safe = np.where(ok, ws, 1.0)
    cx = np.where(ok, wx / safe, ux / count)
    cy = np.where(ok, wy / safe, uy / count)
    return np.stack([cx, cy], axis=1), peak[1:]


def _longest_skeleton_paths(mask: np.ndarray, labels: np.ndarray, n: int) -> list[tuple[np.ndarray | None, float]]:
    """Per piece: the skeleton's (approximate) geodesic diameter as (m, 2) pixel (row, col) from
    one end to the other, and its length in px; ``(None, 0.0)`` if the piece has no skeleton."""
    pixels, graph = skeleton_distance_graph(skeletonize(mask))
    out: list[tuple[np.ndarray | None, float]] = [(None, 0.0)] * n
    if len(pixels) == 0:
        return out
    piece = labels[pixels[:, 0], pixels[:, 1]]  # 1..n; pixels come in raster order

    present, first = np.unique(piece, return_index=True)
    dist = csgraph.dijkstra(graph, directed=False, indices=first, min_only=True)
    far1 = _farthest_per_piece(dist, piece)
    dist, pred, _ = csgraph.dijkstra(graph, directed=False, indices=far1, min_only=True, return_predecessors=True)
    far2 = _farthest_per_piece(dist, piece)

    for start, end, k in zip(far1, far2, present):
        nodes = [end]
        while nodes[-1] != start:
            nodes.append(pred[nodes[-1]])
        nodes = np.array(nodes[::-1])
        out[k - 1] = (pixels[nodes], float(dist[end]))
    return out


def _farthest_per_piece(dist: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """Node of largest finite ``dist`` within each piece (pieces in increasing order). An
    unreachable node (a piece whose skeleton fell apart) never wins over a reachable one."""
    d = np.where(np.isfinite(dist), dist, -1.0)
    order = np.lexsort((d, piece))
    last = np.flatnonzero(np.diff(piece[order], append=piece[order][-1] + 1))
    return order[last]


def _empty() -> BoundaryGraph:
    return BoundaryGraph(vertex_kinds=[], edge_kinds=[], edge_polylines=[], edge_scores=np.zeros(0))
