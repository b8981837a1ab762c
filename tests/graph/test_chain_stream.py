"""Chains found edge by edge, with vertices declared final along the way, are the chains of the
whole graph: the same edges together, each a valid walk, in the fixed form."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph.chain_stream import ChainStream
from csboundary.graph.chains import chains


@st.composite
def graphs_in_pieces(draw):
    """A random multigraph (paths, loops, junctions, self-loops) and an order to give its edges in,
    cut into pieces; each vertex is declared final after the piece holding its last edge, or later."""
    n = draw(st.integers(2, 12))
    edges = draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), min_size=1, max_size=25))
    order = draw(st.permutations(range(len(edges))))
    cuts = sorted(draw(st.sets(st.integers(1, len(edges)), max_size=5)) | {len(edges)})
    delay = draw(st.lists(st.integers(0, 2), min_size=n, max_size=n))
    return n, np.array(edges, np.int64), list(order), cuts, delay


def _stream(n, edges, order, cuts, delay):
    stream, found = ChainStream(), []
    pieces = [order[a:b] for a, b in zip([0, *cuts], cuts)]
    last_piece = {}
    for k, piece in enumerate(pieces):
        for e in piece:
            for x in edges[e]:
                last_piece[int(x)] = k
    due: dict[int, list[int]] = {}
    for x, k in last_piece.items():
        due.setdefault(min(k + delay[x], len(pieces) - 1), []).append(x)
    for k, piece in enumerate(pieces):
        for e in piece:
            stream.add_edge(e, int(edges[e, 0]), int(edges[e, 1]))
        found += stream.finish_vertices(due.get(k, []))
    assert stream.pending_edges == 0
    return found


@settings(max_examples=300, deadline=None)
@given(graphs_in_pieces())
def test_streamed_chains_are_the_whole_graph_s(case):
    n, edges, order, cuts, delay = case
    found = _stream(n, edges, order, cuts, delay)
    expected = chains(n, edges)
    assert sorted(sorted(c.edges) for c in found) == sorted(sorted(e) for e in expected.edges)
    degree = np.bincount(edges.ravel(), minlength=n)
    for chain in found:
        assert len(chain.vertices) == len(chain.edges) + 1
        for k, (e, back) in enumerate(zip(chain.edges, chain.reversed)):
            u, v = edges[e]
            a, b = (v, u) if back else (u, v)
            assert (a, b) == (chain.vertices[k], chain.vertices[k + 1])
        inner = chain.vertices[1:-1]
        assert all(degree[x] == 2 for x in inner)
        if chain.vertices[0] != chain.vertices[-1]:  # open: from the lower-numbered end, both ends anchors
            assert chain.vertices[0] < chain.vertices[-1]
            assert degree[chain.vertices[0]] != 2 and degree[chain.vertices[-1]] != 2
        elif all(degree[x] == 2 for x in chain.vertices):  # a loop: from its lowest edge's u, along it
            assert chain.edges[0] == min(chain.edges) and chain.vertices[0] == edges[chain.edges[0], 0]


@settings(max_examples=100, deadline=None)
@given(graphs_in_pieces())
def test_the_order_edges_come_in_does_not_change_the_chains(case):
    n, edges, order, cuts, delay = case
    in_order = _stream(n, edges, sorted(order), [len(edges)], [0] * n)
    streamed = _stream(n, edges, order, cuts, delay)
    key = lambda chains: sorted((c.edges, c.vertices, c.reversed) for c in chains)  # noqa: E731
    assert key(streamed) == key(in_order)


def test_an_edge_at_a_final_vertex_is_refused():
    stream = ChainStream()
    stream.add_edge(0, 0, 1)
    stream.add_edge(1, 1, 2)
    stream.finish_vertices([1])
    with pytest.raises(ValueError, match="final"):
        stream.add_edge(2, 1, 3)
