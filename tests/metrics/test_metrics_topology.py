"""APLS (both variants) and TLTS: resampling, shortest paths and hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from csboundary.graph import BoundaryGraph
from csboundary.metrics import MetricConfig, apls_paper, apls_symmetric, evaluate_city, paths, tlts
from csboundary.metrics.apls import paper_pairs
from csboundary.metrics.sampling import Segments, boundary_pairs, clip, flatten, resample

EXHAUSTIVE = MetricConfig(exhaustive_pairs=True)


def lines(*polylines) -> BoundaryGraph:
    return BoundaryGraph.from_polylines([np.asarray(p, dtype=float) for p in polylines])


GT = lines([[0, 0], [300, 0]])  # one boundary: 10 pieces of 30 px, 11 vertices at x = 0, 30, ..., 300
GAP = lines([[0, 0], [120, 0]], [[160, 0], [300, 0]])  # the same with x = 120..160 (40 px) cut out


# -- resampling -----------------------------------------------------------------------------------
def test_straight_line_resamples_every_30_px():
    s = resample(flatten(GT), 30)
    assert s.n_vertices == 11 and s.n_components == 1
    assert sorted(s.points[:, 0].tolist()) == pytest.approx(list(range(0, 301, 30)))
    assert s.edge_w.tolist() == pytest.approx([30.0] * 10)


def test_pieces_are_equal_and_at_most_the_spacing():
    s = resample(flatten(lines([[0, 0], [310, 0]])), 30)  # ceil(310 / 30) = 11 pieces of 28.18 px
    assert s.n_vertices == 12 and s.edge_w == pytest.approx(np.full(11, 310 / 11))


def test_closed_ring_is_one_cycle():
    square = lines([[0, 0], [100, 0], [100, 100], [0, 100], [0, 0]])  # 400 px -> 14 pieces
    s = resample(flatten(square), 30)
    assert s.n_vertices == 14 and len(s.edge_u) == 14 and s.n_components == 1
    far = dijkstra(s.matrix, directed=False, indices=[0]).max()
    assert far == pytest.approx(200.0)  # the opposite point of the ring, either way round


def test_junction_vertices_are_kept_and_chains_meet_there():
    t = lines([[0, 0], [90, 0]], [[90, 0], [180, 0]], [[90, 0], [90, 60]])
    s = resample(flatten(t), 30)
    assert s.n_vertices == 4 + 2 + 2 + 1  # junction, bar ends and stem end; 2 + 2 + 1 interior samples
    assert any(np.allclose(p, [90, 0]) for p in s.points)


def test_edge_polylines_are_followed_not_their_chords():
    arc = np.array([[0, 0], [30, 40], [60, 0]], float)  # 100 px along, 60 px as the crow flies
    for line in (arc, arc[::-1]):  # stored either way round
        g = BoundaryGraph(np.array([[0, 0], [60, 0]]), np.array([[0, 1]]), edge_polylines=[line])
        s = resample(flatten(g), 30)
        assert s.edge_w.sum() == pytest.approx(100.0) and s.n_vertices == 5
        assert s.points[:, 1].max() == pytest.approx(40.0)  # 4 pieces of 25 px: the apex is a sample


def test_isolated_vertex_is_its_own_component():
    g = BoundaryGraph(np.array([[0, 0], [90, 0], [500, 500]]), np.array([[0, 1]]))
    s = resample(flatten(g), 30)
    assert s.n_vertices == 5 and s.n_components == 2


def test_locate_projects_onto_the_chain():
    s = resample(flatten(GT), 30)
    found, where = s.locate(np.array([[75.0, 4.0], [75.0, 11.0]]), buffer=10)
    assert found.tolist() == [True, False]
    # the line is one chain between its two end keys (x = 0 and x = 300): 75 px from one, 225 from the other
    keys = s.vertex_key >= 0
    key_points = np.empty((keys.sum(), 2))
    key_points[s.vertex_key[keys]] = s.points[keys]
    assert sorted(key_points[where.exit_key[0], 0].tolist()) == [0.0, 300.0]
    assert sorted(where.exit_off[0].tolist()) == pytest.approx([75.0, 225.0])


def test_rings_need_no_search_and_junctions_connect_chains():
    ring = lines([[0, 0], [100, 0], [100, 100], [0, 100], [0, 0]])
    s = resample(flatten(ring), 30)
    assert s.key_matrix.shape == (1, 1)  # one anchor key, the ring is a loop on it
    a, b = np.triu_indices(s.n_vertices, k=1)
    assert np.allclose(paths.pair_distances(s, a, b), dijkstra(s.matrix, directed=False)[a, b])


def test_clip_keeps_inner_vertices_and_cuts_at_the_border():
    seg = flatten(lines([[-50, 10], [50, 10], [50, 80]]))
    part = clip(seg, 0, 0, 100, 50)
    assert part.n_edges == 2
    assert sorted(map(tuple, part.points.tolist())) == [(0.0, 10.0), (50.0, 10.0), (50.0, 50.0)]


# -- shortest paths ---------------------------------------------------------------------------------
def lattice(rng: np.random.Generator, n: int = 14, cell: float = 70.0) -> BoundaryGraph:
    """A jittered street lattice with a fifth of its links missing, plus loose random walks."""
    xy = np.stack(np.meshgrid(np.arange(n), np.arange(n)), axis=-1).reshape(-1, 2) * cell + rng.normal(0, 8, (n * n, 2))
    idx = np.arange(n * n).reshape(n, n)
    links = np.concatenate(
        [np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1), np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)]
    )
    links = links[rng.random(len(links)) > 0.2]
    walks = [
        np.cumsum(rng.normal(0, 20, (rng.integers(2, 40), 2)), axis=0) + rng.uniform(0, 3000, 2) for _ in range(20)
    ]
    return BoundaryGraph.from_polylines([xy[[u, v]] for u, v in links] + walks)


def test_pair_distances_match_plain_dijkstra(monkeypatch):
    rng = np.random.default_rng(3)
    s = resample(flatten(lattice(rng)), 25)
    assert s.key_matrix.shape[0] > 150  # junctions: the key graph is exercised, not only chains
    src, dst = rng.integers(0, s.n_vertices, (2, 4000))
    full = dijkstra(s.matrix, directed=False)[src, dst]
    limit = rng.uniform(0, 600, len(src))
    assert np.isfinite(full).mean() > 0.3
    for block, budget in ((paths.BLOCK, paths.BUDGET), (64, 500)):  # also tiny blocks and chunks
        monkeypatch.setattr(paths, "BLOCK", block)
        monkeypatch.setattr(paths, "BUDGET", budget)
        got = paths.pair_distances(s, src, dst)
        assert np.array_equal(np.isinf(got), np.isinf(full))
        assert np.allclose(got[np.isfinite(got)], full[np.isfinite(full)], rtol=1e-12)
        limited = paths.pair_distances(s, src, dst, limit=limit)
        inside, beyond = full <= limit - 1e-9, full > limit + 1e-9
        assert np.allclose(limited[inside], full[inside], rtol=1e-12) and np.isinf(limited[beyond]).all()


def test_projected_points_match_dijkstra_on_inserted_vertices():
    # points projected onto the geometry behave as if they were inserted as vertices
    rng = np.random.default_rng(4)
    g = lattice(rng, n=6)
    s = resample(flatten(g), 25)
    query = rng.uniform(0, 350, (60, 2))
    found, where = s.locate(query, buffer=40)
    assert found.sum() > 20
    idx = np.flatnonzero(found)
    a, b = np.triu_indices(len(idx), k=1)
    got = paths.location_distances(s, where.take(idx[a]), where.take(idx[b]))
    # reference: split the flattened graph at the projected points and run plain Dijkstra
    seg = flatten(g)
    pts, edges = list(seg.points), [tuple(e) for e in seg.edges]
    ids = []
    for q in query[idx]:
        here = np.array(pts)
        pa, pb = here[[e[0] for e in edges]], here[[e[1] for e in edges]]
        d = pb - pa
        t = np.clip(((q - pa) * d).sum(1) / np.maximum((d**2).sum(1), 1e-12), 0, 1)
        dist = np.linalg.norm(pa + t[:, None] * d - q, axis=1)
        k = int(np.argmin(dist))
        u, v = edges.pop(k)
        pts.append(here[u] + t[k] * (here[v] - here[u]))
        ids.append(len(pts) - 1)
        edges += [(u, ids[-1]), (ids[-1], v)]
    from scipy.sparse import coo_matrix

    pts, e = np.array(pts), np.array(edges)
    w = np.maximum(np.linalg.norm(pts[e[:, 0]] - pts[e[:, 1]], axis=1), 1e-9)
    m = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(pts), len(pts))).tocsr()
    ref = dijkstra(m, directed=False, indices=ids)[a, np.array(ids)[b]]
    assert np.array_equal(np.isinf(got), np.isinf(ref))
    assert np.allclose(got[np.isfinite(got)], ref[np.isfinite(ref)], rtol=1e-9, atol=1e-6)


# -- identical graphs, shifts, empties ------------------------------------------------------------------
def test_identical_graphs_score_one():
    city = lines([[0, 0], [300, 0], [300, 200]], [[0, 100], [200, 100]], [[400, 0], [400, 300], [600, 300], [400, 0]])
    assert apls_paper(city, city) == 1.0
    result = tlts(city, city)
    assert (result.score, result.too_long, result.too_short, result.infeasible) == (1.0, 0.0, 0.0, 0.0)
    assert apls_symmetric(city, city).score == pytest.approx(1.0, abs=1e-12)


def test_three_pixel_shift_keeps_paths():
    shifted = lines([[0, 3], [300, 3]])
    assert apls_paper(shifted, GT, config=EXHAUSTIVE) == 1.0 and tlts(shifted, GT, config=EXHAUSTIVE).score == 1.0
    assert apls_symmetric(shifted, GT).score == pytest.approx(1.0)


def test_snap_of_50_px_or_more_costs_one():
    assert apls_paper(lines([[0, 49.9], [300, 49.9]]), GT, config=EXHAUSTIVE) == 1.0
    assert apls_paper(lines([[0, 50], [300, 50]]), GT, config=EXHAUSTIVE) == 0.0
    assert tlts(lines([[0, 50], [300, 50]]), GT, config=EXHAUSTIVE).infeasible == 1.0
    # the symmetric variant's buffer is 10 px onto edges
    assert apls_symmetric(lines([[0, 10], [300, 10]]), GT).score == pytest.approx(1.0)
    assert apls_symmetric(lines([[0, 10.5], [300, 10.5]]), GT).score == 0.0


def test_empty_prediction_scores_zero_everywhere():
    empty = BoundaryGraph()
    result = evaluate_city(empty, GT)
    assert all(v == 0.0 for k, v in result["metrics"].items() if k != "tlts_infeasible")
    assert result["metrics"]["tlts_infeasible"] == 1.0
    assert evaluate_city(empty, GT, apls="symmetric")["metrics"]["apls"] == 0.0


# -- the 40 px gap, by hand --------------------------------------------------------------------------------
# Ground truth: 11 vertices x = 0, 30, ..., 300. Prediction: piece A = 0..120 (4 pieces of 30 px:
# vertices 0, 30, 60, 90, 120) and piece B = 160..300 (140 px -> 5 pieces of 28 px: vertices 160,
# 188, 216, 244, 272, 300). Ground-truth vertices snap: x <= 120 onto themselves; 150 -> 160 (10 px;
# 120 is 30 px away), 180 -> 188, 210 -> 216, 240 -> 244, 270 -> 272, 300 -> 300: on B the map is
# x -> 160 + (x - 150) * 28 / 30, so every B-B pair has L_pred = 28/30 L_gt, cost 1/15 (> phi: too short).
# Of the 55 pairs: 10 A-A (cost 0, correct), 15 B-B (cost 1/15, too short), 30 A-B (no path: cost 1, infeasible).
def hand_cost(x1: float, x2: float) -> tuple[float, str]:
    a1, a2 = x1 <= 120, x2 <= 120
    if a1 and a2:
        return 0.0, "correct"
    if not a1 and not a2:
        return 1 / 15, "too_short"
    return 1.0, "infeasible"


def test_gap_exhaustive_by_hand():
    assert apls_paper(GAP, GT, config=EXHAUSTIVE) == pytest.approx(1 - (30 * 1 + 15 / 15) / 55)  # 24/55
    result = tlts(GAP, GT, config=EXHAUSTIVE)
    assert result.n_pairs == 55
    assert (result.score, result.too_short, result.too_long, result.infeasible) == pytest.approx(
        (10 / 55, 15 / 55, 0, 30 / 55)
    )


@pytest.mark.parametrize("seed", [0, 1, 2, 7, 42])
def test_gap_random_pairs_by_hand(seed):
    # 11 vertices > 5 -> 11 // 3 = 3 random pairs; each pair's value is read off the table above
    gt_s, pred_s = resample(flatten(GT), 30), resample(flatten(GAP), 30)
    pairs = paper_pairs(gt_s, pred_s, np.random.default_rng(seed))
    assert pairs.n_pairs == 3
    table = [hand_cost(gt_s.points[a, 0], gt_s.points[b, 0]) for a, b in zip(pairs.src, pairs.dst)]
    assert apls_paper(GAP, GT, seed=seed) == pytest.approx(1 - np.mean([c for c, _ in table]))
    result = tlts(GAP, GT, seed=seed)
    assert result.score == pytest.approx(np.mean([k == "correct" for _, k in table]))
    assert result.too_short == pytest.approx(np.mean([k == "too_short" for _, k in table]))
    assert result.infeasible == pytest.approx(np.mean([k == "infeasible" for _, k in table]))


def test_gap_symmetric_by_hand():
    # gt -> pred: control points project onto the prediction's edges; only x = 150 moves (to 160,
    # 10 px <= buffer). Pairs (150, x) for x = 180..300 cost 10 / (x - 150); A-B pairs cost 1.
    forward = 1 - (30 + sum(10 / d for d in (30, 60, 90, 120, 150))) / 55
    # pred -> gt: the prediction's 5 + 6 control points lie on the ground truth: 10 + 15 pairs, all exact
    result = apls_symmetric(GAP, GT)
    assert result.gt_to_pred == pytest.approx(forward) and result.pred_to_gt == pytest.approx(1.0)
    assert result.score == pytest.approx(2 * forward / (forward + 1))
    assert (result.n_pairs_gt, result.n_pairs_pred) == (55, 25)


def test_detour_is_too_long():
    detour = lines([[0, 0], [120, 0], [150, 40], [180, 0], [300, 0]])  # 60 px replaced by 100 px
    result = tlts(detour, GT, config=EXHAUSTIVE)
    assert result.too_long > 0 and result.infeasible == 0
    assert apls_paper(detour, GT, config=EXHAUSTIVE) < 1


# -- extra boundaries ----------------------------------------------------------------------------------
def test_extra_boundaries_lower_precision_and_symmetric_apls_only():
    # a copy of the ground truth plus a second line 300 px away (out of every snap radius).
    extra = lines([[0, 0], [300, 0]], [[0, 300], [300, 300]])
    paper = evaluate_city(extra, GT)["metrics"]
    assert paper["apls"] == 1.0 and paper["tlts"] == 1.0
    assert paper["precision@5"] == pytest.approx(0.5) and paper["recall@5"] == 1.0
    sym = apls_symmetric(extra, GT)
    # gt -> pred: 55 exact pairs -> 1. pred -> gt: 55 exact + 55 pairs on the extra line, whose
    # control points find no ground-truth edge within 10 px -> cost 1 -> 0.5. Harmonic mean 2/3.
    assert sym.gt_to_pred == pytest.approx(1.0) and sym.pred_to_gt == pytest.approx(0.5)
    assert sym.score == pytest.approx(2 / 3)


# -- seeds ------------------------------------------------------------------------------------------------
def test_equal_seeds_give_identical_results_and_other_seeds_other_pairs():
    rng = np.random.default_rng(0)
    rings = [np.cumsum(rng.normal(0, 25, (60, 2)), axis=0) + rng.uniform(0, 2000, 2) for _ in range(12)]
    gt = BoundaryGraph.from_polylines(rings)
    pred = BoundaryGraph(gt.vertices + rng.normal(0, 2, gt.vertices.shape), gt.edges[rng.random(gt.n_edges) > 0.05])
    for variant in ("paper", "symmetric"):
        a = evaluate_city(pred, gt, apls=variant, seed=5)
        b = evaluate_city(pred, gt, apls=variant, seed=5)
        assert a == b
    gt_s = resample(flatten(gt), 30)
    one = boundary_pairs(gt_s, np.random.default_rng(5))
    two = boundary_pairs(gt_s, np.random.default_rng(6))
    assert not np.array_equal(one[0], two[0])
    assert np.all(one[0] != one[1])  # two distinct vertices per pair


def test_small_boundaries_get_no_pairs():
    short = lines([[0, 0], [150, 0]])  # 5 pieces -> 6 vertices > 5: 2 pairs
    shorter = lines([[0, 0], [120, 0]])  # 4 pieces -> 5 vertices: no pair -> undefined
    assert tlts(short, short).n_pairs == 2
    assert np.isnan(apls_paper(shorter, shorter)) and tlts(shorter, shorter).n_pairs == 0


def test_empty_segments_resample_to_nothing():
    s = resample(Segments.empty(), 30)
    assert s.n_vertices == 0 and s.n_components == 0


def test_paper_pairs_tell_a_broken_boundary_from_a_whole_one():
    # One straight boundary of 400 px; the prediction is the same line cut in two halves 20 px
    # apart: pairs across the cut are disconnected, pairs on one side cost nothing.
    from csboundary.metrics import apls_paper_pairs

    gt = BoundaryGraph(np.array([[0.0, 100], [400, 100]]), np.array([[0, 1]]))
    whole = apls_paper_pairs(gt, gt)
    assert whole.n_pairs > 0 and whole.connected.all() and apls_paper(gt, gt) == 1.0
    cut = BoundaryGraph(np.array([[0.0, 100], [190, 100], [210, 100], [400, 100]]), np.array([[0, 1], [2, 3]]))
    pairs = apls_paper_pairs(cut, gt)
    assert pairs.matched.all() and 0 < pairs.connected.sum() < pairs.n_pairs
    assert apls_paper(cut, gt) == pytest.approx(pairs.connected.mean(), abs=0.05)
