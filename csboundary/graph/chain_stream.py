"""Chains of a graph that arrives edge by edge: the merged boundaries of a city written band by band.

A chain (:mod:`csboundary.graph.chains`) runs through vertices of degree 2, so it is known only
once the degree of each of its vertices is final. The caller adds edges as they come and says
which vertices are final (no later edge can touch them); :meth:`ChainStream.finish_vertices`
returns the chains that became complete, and forgets their edges, so only the chains still
crossing the unfinished part of the city are held.

Each chain is given in a fixed form, whatever the order its edges came in: an open chain runs
from its lower-numbered end (from its lower-numbered edge when both ends are one vertex); a
closed loop of degree-2 vertices starts at the first vertex of its lowest-numbered edge and runs
along that edge. Chains found together are returned by their lowest edge number.
"""

from __future__ import annotations

from collections import defaultdict
from typing import NamedTuple


class StreamChain(NamedTuple):
    vertices: list[int]  # n + 1, first == last for a loop
    edges: list[int]  # n, in walk order
    reversed: list[bool]  # True where an edge is walked from its v to its u


class ChainStream:
    """Pending edges and vertex degrees near the part of the graph still to come."""

    def __init__(self) -> None:
        self._ends: dict[int, tuple[int, int]] = {}  # pending edge -> (u, v)
        self._slots: dict[int, list[int]] = defaultdict(list)  # vertex -> its pending edges (a self-loop twice)
        self._degree: dict[int, int] = defaultdict(int)
        self._final: set[int] = set()

    @property
    def pending_edges(self) -> int:
        return len(self._ends)

    def holds(self, vertex: int) -> bool:
        """Whether ``vertex`` has an edge on a chain not complete yet."""
        return vertex in self._slots

    def add_edge(self, edge: int, u: int, v: int) -> None:
        if u in self._final or v in self._final:
            raise ValueError(f"edge {edge} touches a vertex already declared final ({u}, {v})")
        self._ends[edge] = (u, v)
        for x in (u, v):
            self._slots[x].append(edge)
            self._degree[x] += 1

    def finish_vertices(self, vertices) -> list[StreamChain]:
        """Declare ``vertices`` final; returns the chains now complete, by lowest edge."""
        fresh = [x for x in vertices if x in self._slots and x not in self._final]
        self._final.update(fresh)
        found = []
        for x in fresh:
            for edge in list(self._slots.get(x, ())):
                if edge in self._ends:
                    chain = self._chain_of(edge)
                    if chain is not None:
                        found.append(chain)
                        self._forget(chain)
        return sorted(found, key=lambda c: min(c.edges))

    def _forget(self, chain: StreamChain) -> None:
        for edge in chain.edges:
            for x in self._ends.pop(edge):
                slots = self._slots[x]
                slots.remove(edge)
                if not slots:
                    del self._slots[x]
                    self._degree.pop(x, None)
                    self._final.discard(x)

    def _extend(self, x: int, came: int, start: int) -> tuple[list[int], list[int], bool] | None:
        """Walk on from vertex ``x``, reached by edge ``came``: (vertices from x, edges after
        ``came``, closed back onto ``start``), or None where a vertex is not final yet."""
        vertices, edges = [x], []
        while True:
            if x not in self._final:
                return None
            if self._degree[x] != 2:
                return vertices, edges, False
            a, b = self._slots[x]
            nxt = b if a == came else a
            if a == b:  # a self-loop: the other slot
                nxt = a
            if nxt == start:
                return vertices, edges, True
            u, v = self._ends[nxt]
            x = v if u == x else u
            edges.append(nxt)
            vertices.append(x)
            came = nxt

    def _chain_of(self, edge: int) -> StreamChain | None:
        u, v = self._ends[edge]
        forward = self._extend(v, edge, edge)
        if forward is None:
            return None
        if forward[2]:  # a closed loop of degree-2 vertices
            return self._loop([u, *forward[0]], [edge, *forward[1]])
        backward = self._extend(u, edge, edge)
        if backward is None:
            return None
        vertices = backward[0][::-1] + forward[0]
        edges = backward[1][::-1] + [edge] + forward[1]
        if vertices[0] > vertices[-1] or (vertices[0] == vertices[-1] and edges[0] > edges[-1]):
            vertices, edges = vertices[::-1], edges[::-1]
        return self._with_directions(vertices, edges)

    def _loop(self, vertices: list[int], edges: list[int]) -> StreamChain:
        """A closed loop (walk order, vertices[0] == vertices[-1]) from the first vertex of its
        lowest edge, along that edge."""
        k = edges.index(min(edges))
        start = self._ends[edges[k]][0]
        order = edges[k:] + edges[:k] if vertices[k] == start else [edges[k]] + edges[:k][::-1] + edges[k + 1 :][::-1]
        return self._with_directions([start, *self._walk_vertices(start, order)], order)

    def _walk_vertices(self, start: int, edges: list[int]) -> list[int]:
        out, x = [], start
        for edge in edges:
            u, v = self._ends[edge]
            x = v if u == x else u
            out.append(x)
        return out

    def _with_directions(self, vertices: list[int], edges: list[int]) -> StreamChain:
        return StreamChain(vertices, edges, [self._ends[e][0] != vertices[k] for k, e in enumerate(edges)])
