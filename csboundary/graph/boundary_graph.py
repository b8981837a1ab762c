"""The road-boundary graph shared by labels, models, metrics and output, and its JSON format.

Vertices are stored in continuous pixel coordinates ``(col, row)`` of one frame (a patch or the
whole mosaic; rasterio's convention, pixel centres at +0.5) plus that frame's affine transform,
so world coordinates are always one multiplication away. An edge may carry a polyline (its
interior shape, e.g. the arc of a rounded corner); otherwise it is a straight segment.

JSON (``format: csboundary-graph``, ``version: 1``)::

    {"format": "csboundary-graph", "version": 1, "crs": "EPSG:32618" | null,
     "transform": [a, b, c, d, e, f] | null,
     "vertices": [{"px": [col, row], "xy": [x, y], "kind": "..."}, ...],
     "edges": [{"u": i, "v": j, "kind": "...", "polyline_px": [[col, row], ...], "score": s,
                "patch": [row, col]}, ...]}

``xy`` is written for readers that want world coordinates and ignored on reading (``px`` and
``transform`` are the truth). ``polyline_px`` includes both end vertices; ``score`` (confidence)
and ``patch`` (the grid patch whose prediction the edge comes from) are optional.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
from affine import Affine
from shapely.geometry import LineString

from csboundary.data.atomic import atomic_path
from csboundary.data.windows import pixel_to_world, world_to_pixel
from csboundary.errors import InputError
from csboundary.graph.polyline import polyline_length

FORMAT = "csboundary-graph"
VERSION = 1


@dataclass
class BoundaryGraph:
    """Undirected graph: ``vertices`` (N, 2) float pixel (col, row); ``edges`` (E, 2) int pairs
    (u, v), whose order is the direction of the edge's polyline when it has one."""

    vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    vertex_kinds: list[str] | None = None
    edge_kinds: list[str] | None = None
    edge_polylines: list[np.ndarray | None] | None = None  # pixel polylines incl. both ends
    edge_scores: np.ndarray | None = None
    edge_patches: np.ndarray | None = None  # (E, 2) int grid (row, col) of the source patch
    transform: Affine | None = None  # pixel -> world of the frame the vertices refer to
    crs: str | None = None

    def __post_init__(self) -> None:
        self.vertices = np.asarray(self.vertices, dtype=float).reshape(-1, 2)
        edges = np.asarray(self.edges, dtype=np.int64).reshape(-1, 2)
        if len(edges) and (edges.min() < 0 or edges.max() >= len(self.vertices)):
            raise ValueError("edge refers to a vertex that does not exist")
        self.edges = edges
        if self.edge_patches is not None:
            self.edge_patches = np.asarray(self.edge_patches, dtype=np.int64).reshape(-1, 2)

    # -- views ------------------------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    def edge_polyline(self, k: int) -> np.ndarray:
        """Pixel polyline of edge ``k`` from vertex u to vertex v (2 points if straight)."""
        u, v = self.edges[k]
        if self.edge_polylines is not None and self.edge_polylines[k] is not None:
            return np.asarray(self.edge_polylines[k], dtype=float)
        return self.vertices[[u, v]]

    def edge_lengths(self) -> np.ndarray:
        """Pixel length of every edge along its polyline."""
        return np.array([polyline_length(self.edge_polyline(k)) for k in range(self.n_edges)], dtype=float)

    def edge_subgraph(self, keep: np.ndarray) -> "BoundaryGraph":
        """The graph of the edges where the (E,) boolean ``keep`` is True and the vertices they
        use (renumbered in their old order); every per-edge and per-vertex field follows."""
        keep = np.asarray(keep, dtype=bool).reshape(-1)
        if len(keep) != self.n_edges:
            raise ValueError(f"keep has {len(keep)} entries for {self.n_edges} edges")
        edges = self.edges[keep]
        used = np.unique(edges)
        renumber = np.full(self.n_vertices, -1, dtype=np.int64)
        renumber[used] = np.arange(len(used))
        picked = np.flatnonzero(keep)
        return BoundaryGraph(
            self.vertices[used],
            renumber[edges],
            vertex_kinds=None if self.vertex_kinds is None else [self.vertex_kinds[i] for i in used],
            edge_kinds=None if self.edge_kinds is None else [self.edge_kinds[k] for k in picked],
            edge_polylines=None if self.edge_polylines is None else [self.edge_polylines[k] for k in picked],
            edge_scores=None if self.edge_scores is None else np.asarray(self.edge_scores)[keep],
            edge_patches=None if self.edge_patches is None else self.edge_patches[keep],
            transform=self.transform,
            crs=self.crs,
        )

    def world_vertices(self) -> np.ndarray:
        return self.to_world(self.vertices)

    def to_world(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) world coordinates of (N, 2) pixel points of this graph's frame."""
        if self.transform is None:
            raise ValueError("graph has no transform: its coordinates are pixels only")
        points = np.asarray(points, float).reshape(-1, 2)
        xs, ys = pixel_to_world(self.transform, points[:, 0], points[:, 1])
        return np.stack([np.atleast_1d(xs), np.atleast_1d(ys)], axis=1).astype(float)

    def to_linestrings(self, world: bool = False) -> list[LineString]:
        """One LineString per edge, in pixels or (``world=True``) world coordinates."""
        out = []
        for k in range(self.n_edges):
            line = self.edge_polyline(k)
            if world:
                xs, ys = pixel_to_world(self.transform, line[:, 0], line[:, 1])
                line = np.stack([xs, ys], axis=1)
            out.append(LineString(line))
        return out

    # -- construction -------------------------------------------------------------------------------
    @classmethod
    def from_polylines(
        cls,
        lines: Sequence[np.ndarray],
        transform: Affine | None = None,
        crs: str | None = None,
        snap: float = 1e-6,
        scores: Sequence[float] | None = None,
    ) -> "BoundaryGraph":
        """A graph whose vertices are the polylines' points (shared points merged within ``snap``).
        ``scores`` (one per line) become the scores of the line's edges; a segment two lines share
        keeps the first line's."""
        points, edges = [], {}
        index: dict[tuple[int, int], int] = {}
        for n, line in enumerate(lines):
            line = np.asarray(line, dtype=float)
            ids = []
            for p in line:
                key = (int(round(p[0] / snap)), int(round(p[1] / snap))) if snap > 0 else (id(p), 0)
                if key not in index:
                    index[key] = len(points)
                    points.append(p)
                ids.append(index[key])
            for a, b in zip(ids, ids[1:]):
                if a != b:
                    edges.setdefault((min(a, b), max(a, b)), np.nan if scores is None else float(scores[n]))
        keys = sorted(edges)
        graph = cls(
            np.array(points).reshape(-1, 2), np.array(keys, dtype=np.int64).reshape(-1, 2), transform=transform, crs=crs
        )
        if scores is not None:
            graph.edge_scores = np.array([edges[k] for k in keys], dtype=float)
        return graph

    @classmethod
    def from_world_lines(
        cls,
        lines: Sequence[LineString],
        transform: Affine,
        crs: str | None = None,
        scores: Sequence[float] | None = None,
    ) -> "BoundaryGraph":
        """Graph of world LineStrings expressed in the pixel frame of ``transform`` (rounded to
        1e-6 px, so a line written from a graph's pixels reads back onto the same pixels and
        rasters), with ``scores`` per line as :meth:`from_polylines` takes them."""
        pixel_lines = []
        for line in lines:
            xy = np.asarray(line.coords)[:, :2]
            cols, rows = world_to_pixel(transform, xy[:, 0], xy[:, 1])
            pixel_lines.append(np.round(np.stack([cols, rows], axis=1), 6))
        return cls.from_polylines(pixel_lines, transform=transform, crs=crs, scores=scores)

    # -- JSON -----------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        world = self.world_vertices() if self.transform is not None else None
        edges = [
            edge_item(
                int(u),
                int(v),
                None if self.edge_kinds is None else self.edge_kinds[k],
                None if self.edge_polylines is None else self.edge_polylines[k],
                None if self.edge_scores is None else float(self.edge_scores[k]),
                self.edge_scores is not None,
                None if self.edge_patches is None else self.edge_patches[k],
            )
            for k, (u, v) in enumerate(self.edges.tolist())
        ]
        return {
            **json_header(self.crs, self.transform),
            "vertices": vertex_items(self.vertices, world, self.vertex_kinds),
            "edges": edges,
        }

    @classmethod
    def from_dict(cls, data: dict, source: str = "<dict>") -> "BoundaryGraph":
        if data.get("format") != FORMAT:
            raise InputError(source, f"not a {FORMAT} JSON file (format={data.get('format')!r})")
        if data.get("version") != VERSION:
            raise InputError(
                source, f"unsupported {FORMAT} version {data.get('version')!r} (this build reads {VERSION})"
            )
        vertices = data.get("vertices", [])
        edges = data.get("edges", [])
        transform = Affine(*data["transform"][:6]) if data.get("transform") else None
        try:
            graph = cls(
                np.array([v["px"] for v in vertices], dtype=float).reshape(-1, 2),
                np.array([[e["u"], e["v"]] for e in edges], dtype=np.int64).reshape(-1, 2),
                vertex_kinds=[v.get("kind", "") for v in vertices] if any("kind" in v for v in vertices) else None,
                edge_kinds=[e.get("kind", "") for e in edges] if any("kind" in e for e in edges) else None,
                edge_polylines=[np.array(e["polyline_px"], dtype=float) if "polyline_px" in e else None for e in edges]
                if any("polyline_px" in e for e in edges)
                else None,
                edge_scores=np.array([np.nan if e.get("score") is None else e["score"] for e in edges], dtype=float)
                if any("score" in e for e in edges)
                else None,
                edge_patches=np.array([e.get("patch", [-1, -1]) for e in edges], dtype=np.int64).reshape(-1, 2)
                if any("patch" in e for e in edges)
                else None,
                transform=transform,
                crs=data.get("crs"),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(source, f"malformed graph ({type(exc).__name__}: {exc})") from exc
        return graph

    def write_json(self, path: str | Path) -> Path:
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_dict()))
        return Path(path)

    @classmethod
    def read_json(cls, path: str | Path) -> "BoundaryGraph":
        path = Path(path)
        if not path.exists():
            raise InputError(path, "file not found")
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(path, f"not JSON ({exc})") from exc
        return cls.from_dict(data, str(path))


def json_header(crs: str | None, transform: Affine | None) -> dict:
    """The fields of a graph.json before its vertices and edges."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "crs": crs,
        "transform": list(transform)[:6] if transform is not None else None,
    }


def vertex_items(vertices: np.ndarray, world: np.ndarray | None, kinds: Sequence[str] | None) -> list[dict]:
    """graph.json's entries of vertices (pixels), with their world coordinates and kinds when known."""
    out = []
    for i, p in enumerate(np.asarray(vertices, float).reshape(-1, 2).tolist()):
        item: dict = {"px": p}
        if world is not None:
            item["xy"] = [float(world[i, 0]), float(world[i, 1])]
        if kinds is not None:
            item["kind"] = kinds[i]
        out.append(item)
    return out


def edge_item(u: int, v: int, kind: str | None, polyline, score: float | None, scored: bool, patch) -> dict:
    """graph.json's entry of one edge; ``scored`` says whether the graph has scores (a missing
    one is written as null: strict JSON has no NaN)."""
    item: dict = {"u": u, "v": v}
    if kind is not None:
        item["kind"] = kind
    if polyline is not None:
        item["polyline_px"] = np.asarray(polyline, dtype=float).round(3).tolist()
    if scored:
        item["score"] = score if score is not None and np.isfinite(score) else None
    if patch is not None:
        item["patch"] = [int(x) for x in patch]
    return item
