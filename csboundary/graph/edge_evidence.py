"""What the pipeline knows about each edge of a finished graph: the numbers an edge confidence
is computed from (:mod:`csboundary.models.confidence_model`).

The evidence of an edge is its own score (AfANet's probability, or the mean map value along a
corner or filled edge), its kind, its shape (length, how far it strays from straight), its
place in the graph (the degree of its ends, the length of the connected piece and of the merged
boundary it belongs to, and how straight that boundary runs, within the group it is given: the
city graph's patch core) and the FPN's maps along it: the boundary map on the line, and the road surface a few pixels to
its left and to its right, since a road boundary has roadway on one side only.

The maps are read through ``sample``: a function of (N, 2) pixel points (col, row) in the
graph's frame returning (N, C) map values in [0, 1] (NaN where unknown). Pure otherwise.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line, merge_chains
from csboundary.graph.fragments import fragment_lengths
from csboundary.graph.polyline import points_along, polyline_length

KINDS = (
    "normal",
    "corner",
    "skeleton",
    "join",
    "attach",
    "seam",
    "outline",
)  # the kinds of predicted edges (others: none of these)
KEYPOINT, BOUNDARY, SURFACE = 0, 1, 2  # channels of the FPN's maps
SIDE_OFFSET_PX = 6.0  # how far to each side the road surface is read
FAR_OFFSET_PX = 16.0  # ... and farther out, past a sidewalk (2.4 m at 0.15 m)
RIDGE_OFFSET_PX = 3.0  # the boundary map here beside the line: a sharp ridge falls off, a smear does not
STEP_PX = 2.0  # spacing of the points read along an edge
MAX_DEGREE = 4  # degrees above this count as this

GRAPH_FEATURES = (
    "score",
    *(f"kind_{k}" for k in KINDS),
    "log_length",
    "sinuosity",
    "degree_min",
    "degree_max",
    "log_piece_length",
    "log_piece_edges",
    "log_chain_length",
    "chain_sinuosity",
)
MAP_FEATURES = (
    "boundary_mean",
    "boundary_min",
    "boundary_p10",
    "keypoint_max",
    "surface_on",
    "surface_high",
    "surface_low",
    "surface_contrast",
    "boundary_ridge",
    "surface_far_high",
    "surface_far_low",
)
CHAIN_FEATURES = (
    "boundary_mean",
    "surface_contrast",
    "surface_high",
    "boundary_ridge",
)  # also averaged over the edge's boundary
MAP_FEATURES = MAP_FEATURES + tuple(f"chain_{f}" for f in CHAIN_FEATURES)
FEATURES = GRAPH_FEATURES + MAP_FEATURES

Sampler = Callable[[np.ndarray], np.ndarray]


def edge_evidence(
    graph: BoundaryGraph,
    sample: Sampler | None = None,
    groups: np.ndarray | None = None,
    degree: np.ndarray | None = None,
) -> np.ndarray:
    """(E, len(FEATURES)) evidence of every edge, in the order of :data:`FEATURES`; the map
    features are NaN without ``sample`` (and the surface ones when the maps have no surface).

    ``groups`` (E,) confines the piece and boundary features to the edges of the same group: the
    city graph groups edges by the patch core their midpoint lies in, so that an edge's evidence
    never depends on how far the city extends and a band of the city can be scored on its own
    (:mod:`csboundary.pipeline.prediction.city_blocks`). ``degree`` (V,) gives the vertices' degrees in a
    larger graph that ``graph`` is part of (default: their degrees in ``graph``)."""
    n = graph.n_edges
    out = np.full((n, len(FEATURES)), np.nan)
    if n == 0:
        return out
    lines = [edge_line(graph, k) for k in range(n)]
    length = np.array([polyline_length(line) for line in lines])
    chord = np.array([float(np.linalg.norm(line[-1] - line[0])) for line in lines])
    kinds = graph.edge_kinds or ["normal"] * n
    if degree is None:
        degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    degree = np.minimum(degree, MAX_DEGREE)
    grouped = _split_by_group(graph, groups)
    piece, piece_length = fragment_lengths(grouped)
    piece_edges = np.bincount(piece, minlength=len(piece_length))
    chain_length, chain_chord, chain_of = np.zeros(n), np.zeros(n), np.zeros(n, np.int64)
    for c, chain in enumerate(
        merge_chains(grouped)
    ):  # the boundary (run through degree-2 vertices) each edge is part of
        chain_of[chain.edges] = c
        chain_length[chain.edges] = polyline_length(chain.polyline)
        chain_chord[chain.edges] = float(np.linalg.norm(chain.polyline[-1] - chain.polyline[0]))
    score = np.full(n, np.nan) if graph.edge_scores is None else np.asarray(graph.edge_scores, float)
    columns = {
        "score": np.nan_to_num(score, nan=1.0),
        **{f"kind_{k}": np.array([kind == k for kind in kinds], float) for k in KINDS},
        "log_length": np.log1p(length),
        "sinuosity": length / np.maximum(chord, 1.0),
        "degree_min": degree[graph.edges].min(axis=1).astype(float),
        "degree_max": degree[graph.edges].max(axis=1).astype(float),
        "log_piece_length": np.log1p(piece_length[piece]),
        "log_piece_edges": np.log1p(piece_edges[piece]),
        "log_chain_length": np.log1p(chain_length),
        "chain_sinuosity": np.minimum(chain_length / np.maximum(chain_chord, 1.0), 10.0),  # a closed loop counts as 10
    }
    if sample is not None:
        columns.update(map_evidence(lines, sample))
        for name in (
            f for f in CHAIN_FEATURES if not np.isnan(columns[f]).all()
        ):  # a short edge borrows the evidence of
            # the boundary it is part of (length-weighted); not the surface's when the maps have none
            weight = np.maximum(length, 1e-6)
            total = np.bincount(chain_of, weights=np.nan_to_num(columns[name]) * weight)
            columns[f"chain_{name}"] = total[chain_of] / np.bincount(chain_of, weights=weight)[chain_of]
    for name, values in columns.items():
        out[:, FEATURES.index(name)] = values
    return out


def _split_by_group(graph: BoundaryGraph, groups: np.ndarray | None) -> BoundaryGraph:
    """``graph`` with every vertex that edges of several groups share split into one vertex per
    group (same position), so that pieces and chains end where the groups meet."""
    if groups is None:
        return graph
    groups = np.asarray(groups, np.int64).reshape(-1)
    if len(groups) != graph.n_edges:
        raise ValueError(f"groups has {len(groups)} entries for {graph.n_edges} edges")
    pairs = np.stack([np.repeat(groups, 2), graph.edges.ravel()], axis=1)  # (group, vertex) of each edge end
    _, first, split = np.unique(pairs, axis=0, return_index=True, return_inverse=True)
    vertices = graph.vertices[graph.edges.ravel()[first]]
    return dataclasses.replace(graph, vertices=vertices, edges=split.reshape(-1, 2).astype(np.int64), vertex_kinds=None)


def map_evidence(lines: list[np.ndarray], sample: Sampler) -> dict[str, np.ndarray]:
    """The :data:`MAP_FEATURES` of each polyline: boundary map mean, minimum and 10th
    percentile on the line, how much it stands above its value :data:`RIDGE_OFFSET_PX` to
    either side, the keypoint map's maximum, and the road surface on the line and
    :data:`SIDE_OFFSET_PX` to either side (the higher and lower side's mean, and the mean
    absolute difference of the two sides point by point) and :data:`FAR_OFFSET_PX` out."""
    points, normals, owner = [], [], []
    for k, line in enumerate(lines):
        pts, nrm = points_along(line, STEP_PX)
        points.append(pts)
        normals.append(nrm)
        owner.append(np.full(len(pts), k))
    pts, nrm, owner = np.concatenate(points), np.concatenate(normals), np.concatenate(owner)
    m = len(pts)
    offsets = (0.0, SIDE_OFFSET_PX, -SIDE_OFFSET_PX, FAR_OFFSET_PX, -FAR_OFFSET_PX, RIDGE_OFFSET_PX, -RIDGE_OFFSET_PX)
    values = sample(np.concatenate([pts + d * nrm for d in offsets]))  # one pass over the maps
    on, left, right, far_left, far_right, ridge_left, ridge_right = (
        values[k * m : (k + 1) * m] for k in range(len(offsets))
    )
    n = len(lines)
    starts = np.searchsorted(owner, np.arange(n))
    stops = np.append(starts[1:], len(owner))
    out = {name: np.full(n, np.nan) for name in MAP_FEATURES}
    has_surface = on.shape[1] > SURFACE
    for k in range(n):
        s = slice(starts[k], stops[k])
        b = on[s, BOUNDARY]
        out["boundary_mean"][k], out["boundary_min"][k], out["boundary_p10"][k] = (
            np.mean(b),
            np.min(b),
            np.percentile(b, 10),
        )
        out["keypoint_max"][k] = np.max(on[s, KEYPOINT])
        out["boundary_ridge"][k] = np.mean(b - np.maximum(ridge_left[s, BOUNDARY], ridge_right[s, BOUNDARY]))
        if has_surface:
            sides = np.sort([np.mean(left[s, SURFACE]), np.mean(right[s, SURFACE])])
            out["surface_on"][k] = np.mean(on[s, SURFACE])
            out["surface_low"][k], out["surface_high"][k] = sides
            out["surface_contrast"][k] = np.mean(np.abs(left[s, SURFACE] - right[s, SURFACE]))
            out["surface_far_low"][k], out["surface_far_high"][k] = np.sort(
                [np.mean(far_left[s, SURFACE]), np.mean(far_right[s, SURFACE])]
            )
    return out
