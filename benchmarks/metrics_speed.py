"""Time APLS (both variants) and TLTS at city scale on a ~20,000-vertex synthetic city graph.

The ground truth is a synthetic test city's road boundaries (``plan_city``, 2x3 tiles of
5000 px at 0.152 m/px, no rendering) resampled to 20,000 vertices (about one every 33 px); the
prediction is a perturbed copy: vertices jittered by 1.5 px, 3 % of edges cut out (gaps), 300
false links between nearby boundaries and 200 spurious 60 px boundaries. Usage:

    .venv/bin/python benchmarks/metrics_speed.py [--vertices 20000] [--tiles 2x3] [--seed 0] [--repeat 3]

Target (metrics issue): APLS paper + APLS symmetric + TLTS in at most 5 s in all on one core.
Each metric is timed on its own from the two BoundaryGraphs (its resampling included); the best
of ``--repeat`` runs is printed. Graph construction is not timed.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from affine import Affine  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from csboundary.data.synth.city import plan_city  # noqa: E402
from csboundary.data.synth.config import SynthConfig  # noqa: E402
from csboundary.graph import BoundaryGraph  # noqa: E402
from csboundary.metrics import MetricConfig, apls_paper, apls_symmetric, evaluate_city, tlts  # noqa: E402
from csboundary.metrics.sampling import flatten, resample  # noqa: E402


def city_graph(tiles: tuple[int, int], seed: int, vertices: int) -> BoundaryGraph:
    config = SynthConfig()
    city = plan_city(config, "test", seed, tiles)
    gt = city.ground_truth()
    rows, cols = tiles
    transform = Affine(
        config.gsd, 0, config.origin_x, 0, -config.gsd, config.origin_y + rows * config.tile_size * config.gsd
    )
    dense = flatten(BoundaryGraph.from_world_lines(list(gt.geometry), transform, crs=config.crs))
    spacing = float(gt.length.sum()) / config.gsd / vertices  # about `vertices` samples in all
    for _ in range(20):  # adjust: chains add their end vertices
        sampled = resample(dense, spacing)
        if abs(sampled.n_vertices - vertices) <= vertices * 0.002:
            break
        spacing *= sampled.n_vertices / vertices
    return BoundaryGraph(
        sampled.points, np.stack([sampled.edge_u, sampled.edge_v], axis=1), transform=transform, crs=config.crs
    )


def perturb(graph: BoundaryGraph, seed: int) -> BoundaryGraph:
    rng = np.random.default_rng(seed)
    pts = graph.vertices + rng.normal(0, 1.5, graph.vertices.shape)
    edges = graph.edges[rng.random(graph.n_edges) > 0.03]
    tree = cKDTree(pts)
    near = np.array(sorted(tree.query_pairs(40.0)))
    links = near[rng.choice(len(near), 300, replace=False)]
    starts = rng.uniform(pts.min(axis=0), pts.max(axis=0), (200, 2))
    angles = rng.uniform(0, 2 * np.pi, 200)
    ends = starts + 60 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    n = len(pts)
    spurious = np.stack([n + 2 * np.arange(200), n + 2 * np.arange(200) + 1], axis=1)
    pts = np.concatenate([pts, np.stack([starts, ends], axis=1).reshape(-1, 2)])
    return BoundaryGraph(pts, np.concatenate([edges, links, spurious]), transform=graph.transform, crs=graph.crs)


def best_of(repeat: int, fn):
    times, value = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return min(times), value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--vertices", type=int, default=20000)
    parser.add_argument("--tiles", default="2x3")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rows, cols = (int(v) for v in args.tiles.split("x"))
    t0 = time.perf_counter()
    gt = city_graph((rows, cols), args.seed, args.vertices)
    pred = perturb(gt, args.seed + 1)
    config = MetricConfig()
    at_30 = resample(flatten(gt), config.spacing).n_vertices, resample(flatten(pred), config.spacing).n_vertices
    print(
        f"graphs built in {time.perf_counter() - t0:.1f} s (not timed below): ground truth {gt.n_vertices} vertices / "
        f"{gt.n_edges} edges, prediction {pred.n_vertices} vertices / {pred.n_edges} edges; "
        f"{at_30[0]} and {at_30[1]} vertices after the metrics' own {config.spacing:g} px resampling"
    )
    t_paper, v_paper = best_of(args.repeat, lambda: apls_paper(pred, gt, seed=args.seed, config=config))
    t_sym, v_sym = best_of(args.repeat, lambda: apls_symmetric(pred, gt, seed=args.seed, config=config))
    t_tlts, v_tlts = best_of(args.repeat, lambda: tlts(pred, gt, seed=args.seed, config=config))
    print(f"APLS paper      {t_paper:6.2f} s   = {v_paper:.4f}")
    print(
        f"APLS symmetric  {t_sym:6.2f} s   = {v_sym.score:.4f} (gt->pred {v_sym.gt_to_pred:.4f} on {v_sym.n_pairs_gt} pairs, "
        f"pred->gt {v_sym.pred_to_gt:.4f} on {v_sym.n_pairs_pred} pairs)"
    )
    print(
        f"TLTS            {t_tlts:6.2f} s   = {v_tlts.score:.4f} "
        f"(too long {v_tlts.too_long:.3f}, too short {v_tlts.too_short:.3f}, "
        f"infeasible {v_tlts.infeasible:.3f}; {v_tlts.n_pairs} pairs)"
    )
    total = t_paper + t_sym + t_tlts
    print(f"all three       {total:6.2f} s   (target <= 5 s on one core: {'met' if total <= 5 else 'MISSED'})")
    for apls in ("paper", "symmetric"):
        t_all, _ = best_of(
            args.repeat, lambda apls=apls: evaluate_city(pred, gt, apls=apls, seed=args.seed, config=config)
        )
        print(f"evaluate_city --apls {apls:9s} (P/R/F1 + APLS + TLTS, pairs shared): {t_all:6.2f} s")


if __name__ == "__main__":
    main()
