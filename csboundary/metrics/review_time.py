"""What a draft saves a reviewer: a simulated review, in minutes (docs/metrics.md, "Review effort").

A reviewer turns a predicted graph into a correct map in two passes:

1. **look** at edges in an order (least sure first, or a random order), deleting each false edge
   (one with less than half its length within 5 px of the ground truth, as
   :func:`csboundary.metrics.confidence.edge_truth` says) and moving a vertex of a true edge
   that strays ``fix_px`` pixels or more off the truth onto it (one click; its pixels off the
   truth go);
2. **draw** what is still missing: every run of ground truth farther than 5 px from the kept
   edges, traced as a polyline that stays within ``trace_tolerance_px`` of it
   (Douglas-Peucker), longest run first. Each run costs a look (to find where it starts) and its
   clicks; an end of a run that meets a kept line snaps onto it and costs no click; a run costs
   at least one click.

Drawing the same map from scratch costs a look and the clicks of every ground-truth boundary
traced the same way. F1@5 is tracked after every action on 1 px rasters, as
:func:`csboundary.metrics.pixel.relaxed_scores` defines it, so the curve starts at the
prediction's F1@5. The reviewer may stop looking early and draw from there (the point of a
confidence: the sure edges need no look); ``minutes_to_target_f1`` is the cheapest such plan that
reaches the target, searched over stopping points.

Pure functions on graphs in one pixel frame; costs are parameters (:class:`ReviewCosts`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import cKDTree

from csboundary.config import Config
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line, merge_chains
from csboundary.graph.polyline import points_along
from csboundary.metrics.confidence import TRUE_SHARE, TRUE_WITHIN_PX, edge_truth
from csboundary.metrics.pixel import f1_score, rasterize
from csboundary.metrics.segments import Segments, flatten

ORDERS = ("confidence", "random")
STOPS = 40  # stopping points searched for the cheapest plan to a target F1


@dataclass(frozen=True)
class ReviewCosts(Config):
    """Seconds per action and the drawing tolerance (defaults argued in docs/metrics.md)."""
    config_name = "review costs"

    look_s: float = 2.0  # jump to an edge (one key) and judge it against the image (a yes/no verification)
    delete_s: float = 1.0  # delete an edge judged false (one more key)
    vertex_s: float = 1.75  # one click on a visible point (extreme clicking: 7 s for 4 clicks)
    trace_tolerance_px: float = 2.0  # a drawn polyline stays this close to the true boundary
    fix_px: float = 5.0  # a true edge with this many pixels off the truth gets a vertex moved (one click) onto it
    target_f1: float = 0.95

    def __post_init__(self) -> None:
        if min(self.look_s, self.delete_s, self.vertex_s, self.fix_px) < 0 or self.trace_tolerance_px <= 0 or not 0 < self.target_f1 <= 1:
            raise ValueError("review costs must be >= 0, the tolerance > 0 and the target F1 in (0, 1]")


def _line_pixels(line: np.ndarray) -> np.ndarray:
    """Distinct 1 px raster pixels (P, 2) of one polyline, as :func:`rasterize` draws them."""
    n = len(line)
    return rasterize(Segments(np.asarray(line, float), np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)))


_HALF = 1 << 30  # pixel coordinates within +-2^30 pack into one non-negative int64


def _keys(pixels: np.ndarray) -> np.ndarray:
    """One int64 per pixel (col, row), for sets and sorting."""
    return ((pixels[:, 0].astype(np.int64) + _HALF) << 32) | (pixels[:, 1].astype(np.int64) + _HALF)


def _pixels(keys: np.ndarray) -> np.ndarray:
    return np.stack([(keys >> 32) - _HALF, (keys & ((1 << 32) - 1)) - _HALF], axis=1)


def clicks_to_trace(line: np.ndarray, tolerance_px: float) -> int:
    """Vertices of ``line`` simplified (Douglas-Peucker) to stay within ``tolerance_px``: the
    clicks to draw it; a closed line needs its first vertex once."""
    line = np.asarray(line, float)
    if len(line) < 2:
        return 0
    simple = shapely.simplify(shapely.LineString(line), tolerance_px, preserve_topology=False)
    count = len(shapely.get_coordinates(simple))
    closed = len(line) > 2 and np.allclose(line[0], line[-1])
    return max(2, count) - (1 if closed else 0)


def scratch_clicks(gt: BoundaryGraph, tolerance_px: float) -> int:
    """Clicks to draw every boundary of ``gt`` from nothing (chains through degree-2 vertices)."""
    return sum(clicks_to_trace(chain.polyline, tolerance_px) for chain in merge_chains(gt))


class _State:
    """Which predicted pixels are kept and which ground-truth pixels they cover, updated edge by
    edge as edges are deleted and runs drawn: F1@5 after every action without re-rasterising."""

    def __init__(self, pred: BoundaryGraph, gt_pixels: np.ndarray, within_px: float):
        self.within = within_px
        self.gt_tree = cKDTree(gt_pixels) if len(gt_pixels) else None
        self.gt_count = len(gt_pixels)
        rows, owner = [], []
        for k in range(pred.n_edges):
            px = _line_pixels(edge_line(pred, k))
            rows.append(px)
            owner.append(np.full(len(px), k))
        rows = np.concatenate(rows) if rows else np.zeros((0, 2), np.int64)
        owner = np.concatenate(owner) if owner else np.zeros(0, np.int64)
        keys, pixel_of_row = np.unique(_keys(rows), return_inverse=True)
        self.pixel_of_row, self.owner = pixel_of_row.ravel(), owner
        self.rows_of_edge = np.split(np.argsort(owner, kind="stable"), np.cumsum(np.bincount(owner, minlength=pred.n_edges))[:-1])
        self.keys = set(keys.tolist())
        self.unique_keys = keys
        unique_px = _pixels(keys)
        self.owners = np.bincount(self.pixel_of_row, minlength=len(keys))  # kept edges through each pixel
        self.pixel_true = self._near_gt(unique_px)
        self.kept, self.kept_true = len(keys), int(self.pixel_true.sum())
        # every (ground-truth pixel, predicted pixel) pair closer than within_px
        self.cover = np.zeros(self.gt_count, np.int64)
        self.pairs_of_pixel: list[np.ndarray] = [np.zeros(0, np.int64)] * len(keys)
        if self.gt_tree is not None and len(keys):
            pairs = cKDTree(unique_px).sparse_distance_matrix(self.gt_tree, np.nextafter(within_px, 0), output_type="ndarray")
            p, g = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
            order = np.argsort(p, kind="stable")
            p, g = p[order], g[order]
            self.pairs_of_pixel = np.split(g, np.cumsum(np.bincount(p, minlength=len(keys)))[:-1])
            np.add.at(self.cover, g, 1)
        self.covered = int((self.cover > 0).sum())

    def copy(self) -> "_State":
        """An independent state (the arrays that change copied, the rest shared)."""
        other = copy.copy(self)
        other.owners, other.cover, other.keys = self.owners.copy(), self.cover.copy(), set(self.keys)
        return other

    def kept_pixels(self) -> np.ndarray:
        """(P, 2) pixels of the kept edges and of the runs drawn so far."""
        return _pixels(np.fromiter(self.keys, np.int64, len(self.keys)))

    def _near_gt(self, pixels: np.ndarray) -> np.ndarray:
        if self.gt_tree is None or not len(pixels):
            return np.zeros(len(pixels), bool)
        return self.gt_tree.query(pixels, k=1, distance_upper_bound=self.within)[0] < self.within

    def f1(self) -> float:
        p = self.kept_true / self.kept if self.kept else 0.0
        r = self.covered / self.gt_count if self.gt_count else float("nan")
        return f1_score(p, r)

    def edge_pixels(self, k: int) -> np.ndarray:
        """Indices of edge ``k``'s distinct pixels."""
        return np.unique(self.pixel_of_row[self.rows_of_edge[k]])

    def off_truth_px(self, k: int) -> int:
        """Pixels of edge ``k`` farther than ``within_px`` from the ground truth."""
        return int(np.count_nonzero(~self.pixel_true[self.edge_pixels(k)]))

    def delete(self, k: int, off_truth_only: bool = False) -> None:
        """Take edge ``k`` out, or only its pixels off the ground truth (a vertex moved onto the
        boundary: what stays is what was on it)."""
        pixels = self.edge_pixels(k)
        if off_truth_only:
            pixels = pixels[~self.pixel_true[pixels]]
        for pixel in pixels.tolist():
            self.owners[pixel] -= 1
            if self.owners[pixel] == 0:
                self.kept -= 1
                self.keys.discard(int(self.unique_keys[pixel]))
                self.kept_true -= int(self.pixel_true[pixel])
                g = self.pairs_of_pixel[pixel]
                self.cover[g] -= 1
                self.covered -= int(np.count_nonzero(self.cover[g] == 0))

    def draw(self, pixels: np.ndarray) -> None:
        """Add a traced run: its pixels count as kept (and true where near the ground truth), and
        cover the ground truth near them."""
        new = np.array([key not in self.keys for key in _keys(pixels).tolist()], bool)
        if not new.any():
            return
        pixels = pixels[new]
        self.keys.update(_keys(pixels).tolist())
        self.kept += len(pixels)
        self.kept_true += int(self._near_gt(pixels).sum())
        if self.gt_tree is not None:
            for g in self.gt_tree.query_ball_point(pixels, np.nextafter(self.within, 0)):
                g = np.asarray(g, np.int64)
                self.covered += int(np.count_nonzero(self.cover[g] == 0))
                self.cover[g] += 1


def boundary_samples(gt: BoundaryGraph) -> list[np.ndarray]:
    """Points every 1 px along each boundary of ``gt`` (chains through degree-2 vertices)."""
    samples = [points_along(chain.polyline, 1.0)[0] for chain in merge_chains(gt)]
    return [pts for pts in samples if len(pts) >= 2]


def missing_runs(samples: list[np.ndarray], kept_pixels: np.ndarray, within_px: float) -> list[tuple[np.ndarray, int]]:
    """Runs of the boundaries ``samples`` (:func:`boundary_samples`) farther than ``within_px``
    from every kept pixel, each with how many of its two ends meet a kept line (and so snap onto
    it)."""
    if not samples:
        return []
    sizes = [len(pts) for pts in samples]
    if len(kept_pixels):
        far_all = cKDTree(kept_pixels).query(np.floor(np.concatenate(samples)), k=1, distance_upper_bound=within_px)[0] >= within_px
    else:
        far_all = np.ones(sum(sizes), bool)
    runs = []
    for pts, far in zip(samples, np.split(far_all, np.cumsum(sizes)[:-1])):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], far.astype(np.int8), [0]])))
        for start, stop in zip(edges[::2], edges[1::2]):
            lo, hi = max(start - 1, 0), min(stop + 1, len(pts))  # reach back onto the kept line it leaves
            runs.append((pts[lo:hi], int(start > 0) + int(stop < len(pts))))
    return runs


@dataclass(frozen=True)
class ReviewTrace:
    """One simulated review: seconds and F1@5 after each action, and its totals."""

    seconds: np.ndarray  # (A + 1,) cumulative, starting at 0
    f1: np.ndarray  # (A + 1,) F1@5 after each action
    look_s: float  # the first pass (the edges looked at, the false ones deleted)
    clicks: int

    @property
    def total_s(self) -> float:
        return float(self.seconds[-1])

    @property
    def draw_s(self) -> float:
        return self.total_s - self.look_s


def _draw(state: _State, samples: list[np.ndarray], seconds: list[float], f1: list[float], costs: ReviewCosts, within_px: float,
          until: float = np.inf) -> ReviewTrace:
    """Trace the missing runs into ``state`` (changed in place), longest first, extending the
    ``seconds`` and ``f1`` of the look pass; stop once F1@5 reaches ``until``."""
    look_s, clicks = seconds[-1], 0
    for run, snapped in sorted(missing_runs(samples, state.kept_pixels(), within_px), key=lambda r: -len(r[0])):
        if f1[-1] >= until:
            break
        n = max(1, clicks_to_trace(run, costs.trace_tolerance_px) - snapped)
        clicks += n
        state.draw(_line_pixels(run))
        seconds.append(seconds[-1] + costs.look_s + n * costs.vertex_s)  # find where it starts, then trace it
        f1.append(state.f1())
    return ReviewTrace(np.asarray(seconds), np.asarray(f1), look_s, clicks)


def simulate_review(state: _State, false: np.ndarray, samples: list[np.ndarray], order: np.ndarray, costs: ReviewCosts, within_px: float,
                    stops: int = STOPS) -> tuple[ReviewTrace, float]:
    """Look at every edge of ``order`` (deleting the false ones), then draw: the full review's
    trace; and the seconds of the cheapest plan "look at the first k edges, then draw runs until
    F1@5 reaches the target", over k at ``stops`` + 1 evenly spread stopping points (NaN if no
    plan reaches it). ``state`` is used up."""
    stop_at = set(np.linspace(0, len(order), stops + 1).round().astype(int).tolist())
    seconds, f1 = [0.0], [state.f1()]
    target = costs.target_f1 - 1e-12
    best = np.inf
    for i in range(len(order) + 1):
        if f1[-1] >= target:
            best = min(best, seconds[-1])
        elif i in stop_at and i < len(order) and seconds[-1] < best:  # a later stop has looked longer: it can only win by drawing less
            trace = _draw(state.copy(), samples, list(seconds), list(f1), costs, within_px, until=target)
            hit = np.flatnonzero(trace.f1 >= target)
            best = min(best, float(trace.seconds[hit[0]])) if len(hit) else best
        if i == len(order):
            break
        k = int(order[i])
        cost = costs.look_s
        if false[k]:
            state.delete(k)
            cost += costs.delete_s
        elif state.off_truth_px(k) >= costs.fix_px:
            state.delete(k, off_truth_only=True)
            cost += costs.vertex_s
        seconds.append(seconds[-1] + cost)
        f1.append(state.f1())
    full = _draw(state, samples, seconds, f1, costs, within_px)
    hit = np.flatnonzero(full.f1 >= target)
    best = min(best, float(full.seconds[hit[0]])) if len(hit) else best
    return full, (best if np.isfinite(best) else float("nan"))


def review_order(pred: BoundaryGraph, order: str, seed: int = 0) -> np.ndarray:
    """Edge indices in the order a reviewer looks at them: ``confidence`` least sure first
    (edges without a score last, in edge order), or ``random`` (seeded)."""
    if order == "confidence":
        scores = np.asarray(pred.edge_scores if pred.edge_scores is not None else np.full(pred.n_edges, np.nan), float)
        return np.argsort(np.where(np.isfinite(scores), scores, np.inf), kind="stable")
    if order == "random":
        return np.random.default_rng(seed).permutation(pred.n_edges)
    raise ValueError(f"review order must be one of {ORDERS}, got {order!r}")


def review_report(pred: BoundaryGraph, gt: BoundaryGraph, metres_per_px: float | None = None, costs: ReviewCosts = ReviewCosts(),
                  seed: int = 0, within_px: float = TRUE_WITHIN_PX, curve_points: int = 21) -> dict:
    """The simulated review of ``pred`` against ``gt`` (one pixel frame), in both orders.

    Returns minutes to a fully corrected map and from scratch, minutes to reach
    ``costs.target_f1``, each also per km of true boundary when ``metres_per_px`` is given, the
    action counts, and the F1@5 curve against minutes (``curve_points`` points per order)."""
    gt_pixels = rasterize(flatten(gt))
    samples = boundary_samples(gt)
    false = edge_truth(pred, gt, within_px) < TRUE_SHARE if pred.n_edges else np.zeros(0, bool)
    gt_length_px = float(gt.edge_lengths().sum()) if gt.n_edges else 0.0
    clicks = scratch_clicks(gt, costs.trace_tolerance_px)
    scratch_s = len(samples) * costs.look_s + clicks * costs.vertex_s
    km = gt_length_px * metres_per_px / 1000 if metres_per_px else None
    out = {"costs": costs.to_dict(), "edges": int(pred.n_edges), "false_edges": int(false.sum()),
           "true_boundary_px": gt_length_px, "true_boundary_km": km,
           "scratch_minutes": scratch_s / 60, "scratch_clicks": clicks, "orders": {}}
    draft = _State(pred, gt_pixels, within_px)  # rasterised and paired once; each order works on a copy
    for name in ORDERS:
        order = review_order(pred, name, seed)
        trace, to_target = simulate_review(draft.copy(), false, samples, order, costs, within_px)
        pick = np.unique(np.linspace(0, len(trace.seconds) - 1, curve_points).round().astype(int))
        out["orders"][name] = {"minutes": trace.total_s / 60, "look_minutes": trace.look_s / 60, "draw_minutes": trace.draw_s / 60,
                               "clicks": trace.clicks, "start_f1": float(trace.f1[0]), "end_f1": float(trace.f1[-1]),
                               "minutes_to_target_f1": to_target / 60,
                               "curve": {"minutes": (trace.seconds[pick] / 60).tolist(), "f1": trace.f1[pick].tolist()}}
    if km:
        out["per_km"] = {"scratch_minutes": out["scratch_minutes"] / km,
                         **{f"{name}_minutes": o["minutes"] / km for name, o in out["orders"].items()},
                         **{f"{name}_minutes_to_target_f1": o["minutes_to_target_f1"] / km for name, o in out["orders"].items()}}
    return out
