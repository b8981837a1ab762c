"""One graph out of pieces that arrive in turn (the blocks of a city graph), without holding it.

Each piece is a :class:`BoundaryGraph` whose vertices the earlier pieces may share: the same
point (exact coordinates) is the same vertex. :class:`GraphStream` numbers the vertices in order
of first use and the edges in order of arrival, and hands back what each piece adds (new
vertices, edges with their numbers); once the caller declares which vertices are final (no later
piece touches them), it returns the boundaries (chains through degree-2 vertices,
:mod:`csboundary.graph.chain_stream`) that became complete, with their edges. It keeps only the
vertices and edges of chains that are not complete yet, and the numbers of vertices a later piece
may still share.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chain_stream import ChainStream, StreamChain
from csboundary.graph.chains import edge_line


@dataclass
class StreamEdge:
    """An edge of the stream: its number, its ends' numbers, its line from u to v (pixels, the
    ends pinned to the vertices), the polyline it was given (None: straight) and its fields."""

    id: int
    u: int
    v: int
    line: np.ndarray
    polyline: np.ndarray | None
    kind: str | None
    score: float | None
    patch: tuple[int, int] | None


@dataclass
class StreamPiece:
    """What one piece adds: the vertices it uses first (numbers ``first_vertex`` on, positions
    and kinds) and its edges in order."""

    first_vertex: int
    vertices: np.ndarray
    vertex_kinds: list[str] | None
    edges: list[StreamEdge]


@dataclass
class StreamBoundary:
    """A complete boundary: the chain and its edges in walk order."""

    chain: StreamChain
    edges: list[StreamEdge]

    @property
    def polyline(self) -> np.ndarray:
        """The pixel line through all its edges, the shared vertices once."""
        pieces = [e.line[::-1] if back else e.line for e, back in zip(self.edges, self.chain.reversed)]
        return np.concatenate([pieces[0]] + [p[1:] for p in pieces[1:]])


class GraphStream:
    """Numbers, degrees and boundaries of a graph given piece by piece (module docstring).

    Each vertex comes with the step after which it is final (the caller knows: for a city, the
    last block that can touch it); :meth:`finish` at a step declares final every vertex due by
    then, completes the boundaries through them and forgets their numbers, in time proportional
    to those vertices alone."""

    def __init__(self) -> None:
        self._ids: dict[tuple[float, float], int] = {}
        self._cells: dict[tuple[int, int], list[tuple[float, float]]] = {}  # 1 px cells of the numbered vertices
        self._due: dict[int, list[tuple[int, tuple[float, float]]]] = {}  # step -> the vertices final after it
        self._done = -1  # the last step finished
        self._edges: dict[int, StreamEdge] = {}  # edges of incomplete chains
        self._chains = ChainStream()
        self.n_vertices = 0
        self.n_edges = 0
        self.close_pairs = 0  # vertex pairs less than 1 px apart

    @property
    def held(self) -> int:
        """Vertices and edges held now (what memory grows with)."""
        return len(self._ids) + len(self._edges)

    def add(self, graph: BoundaryGraph, final_step: np.ndarray | None = None) -> StreamPiece:
        """Number ``graph``'s vertices and edges; returns what it adds. ``final_step`` (V,):
        the step after which each vertex is final (default 0)."""
        first = self.n_vertices
        ids = np.empty(graph.n_vertices, np.int64)
        steps = np.zeros(graph.n_vertices, np.int64) if final_step is None else np.asarray(final_step, np.int64)
        new = []
        for k, point in enumerate(graph.vertices.tolist()):
            key = (point[0], point[1])
            found = self._ids.get(key)
            if found is None:
                step = int(steps[k])
                if step <= self._done:
                    raise ValueError(f"vertex {key} is new after step {self._done}, past its final step {step}")
                found = self._ids[key] = self.n_vertices
                self.n_vertices += 1
                new.append(k)
                self._count_close(key)
                self._due.setdefault(step, []).append((found, key))
            ids[k] = found
        edges = []
        for k, (a, b) in enumerate(graph.edges.tolist()):
            u, v = int(ids[a]), int(ids[b])
            polyline = None if graph.edge_polylines is None else graph.edge_polylines[k]
            edge = StreamEdge(
                self.n_edges,
                u,
                v,
                edge_line(graph, k),
                None if polyline is None else np.asarray(polyline, float),
                None if graph.edge_kinds is None else graph.edge_kinds[k],
                None if graph.edge_scores is None else float(graph.edge_scores[k]),
                None if graph.edge_patches is None else (int(graph.edge_patches[k][0]), int(graph.edge_patches[k][1])),
            )
            self.n_edges += 1
            edges.append(edge)
            self._edges[edge.id] = edge
            self._chains.add_edge(edge.id, u, v)
        kinds = None if graph.vertex_kinds is None else [graph.vertex_kinds[k] for k in new]
        return StreamPiece(first, graph.vertices[new].reshape(-1, 2), kinds, edges)

    def finish(self, step: int | None = None) -> list[StreamBoundary]:
        """Declare final the vertices due by ``step`` (None: all of them) and forget their
        numbers; returns the boundaries now complete, by lowest edge number."""
        due = sorted(k for k in self._due if step is None or k <= step)
        final = []
        for k in due:
            for vertex, key in self._due.pop(k):
                final.append(vertex)
                del self._ids[key]
                cell = self._cells[_cell(key)]
                cell.remove(key)
                if not cell:
                    del self._cells[_cell(key)]
        if step is not None:
            self._done = max(self._done, step)
        return [
            StreamBoundary(chain, [self._edges.pop(e) for e in chain.edges])
            for chain in self._chains.finish_vertices(final)
        ]

    def _count_close(self, key: tuple[float, float]) -> None:
        cx, cy = _cell(key)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for other in self._cells.get((cx + dx, cy + dy), ()):
                    if (other[0] - key[0]) ** 2 + (other[1] - key[1]) ** 2 < 1.0:
                        self.close_pairs += 1
        self._cells.setdefault((cx, cy), []).append(key)


def _cell(key: tuple[float, float]) -> tuple[int, int]:
    return int(np.floor(key[0])), int(np.floor(key[1]))
