"""What a draft saves a reviewer: a simulated review, in minutes (docs/metrics.md, "Review effort").

The unit a person checks is a **boundary**: a maximal chain of the graph between junctions and
ends (:func:`csboundary.graph.chains.merge_chains`), with its own confidence (the
length-weighted mean of its edges' calibrated scores: the expected share of its length that is
true). The chains are rebuilt from the lines' shared ends, so a prediction read from graph.json,
its GeoPackage or its GeoJSON is the same set of boundaries and costs the same minutes.

1. **The review draft.** A scored boundary is shown only when it is expected to save time
   (:func:`keeps_boundary`): ``p x seconds to draw it > seconds to look at it + (1 - p) x
   seconds to delete it``. The rest is held back (``predict`` still writes it, marked), so in
   expectation a draft never costs more than drawing from scratch.
2. **Look** at the draft's boundaries in an order (least sure first, or a random order) and act
   on each. A boundary with less than half its length within 5 px of the ground truth is
   deleted. Otherwise each run of it off the truth is mended: a run of ``cut_px`` or longer is
   cut out (a cut at each end that is not the boundary's end, then a delete), a shorter one of
   ``fix_px`` or more gets a vertex moved onto the truth (its pixels off the truth go, and the
   line runs straight across where it strayed).
3. **Draw** what is still missing: every run of ground truth farther than 5 px from the kept
   lines, traced as a polyline that stays within ``trace_tolerance_px`` of it (Douglas-Peucker),
   longest run first; a run that meets a kept line and is no longer than ``fix_px`` (beyond the
   samples that reach back onto it) is left, as a stray that short is. Each run costs
   finding where it starts, its clicks (an end that meets a
   kept line snaps onto it and costs no click; a run costs at least one click) and the eye
   travel along its length.

Drawing the same map from scratch costs the same for every ground-truth boundary. F1@5 is
tracked after every action on 1 px rasters, as :func:`csboundary.metrics.pixel.relaxed_scores`
defines it, so the curve starts at the draft's F1@5. The reviewer may stop looking early and
draw from there (the point of a confidence: the sure boundaries need no look);
``minutes_to_target_f1`` is the cheapest such plan that reaches the target, searched over
stopping points.

Pure functions on graphs in one pixel frame; costs are parameters (:class:`ReviewCosts`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import cKDTree

from csboundary.config import Config
from csboundary.graph.boundaries import Boundary, graph_boundaries
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import merge_chains
from csboundary.graph.polyline import points_along, polyline_between, polyline_length
from csboundary.metrics.confidence_quality import TRUE_SHARE, TRUE_WITHIN_PX
from csboundary.metrics.pixel import rasterize
from csboundary.metrics.review_pixels import PixelState, line_pixels, piece_pixels
from csboundary.metrics.segments import flatten

ORDERS = ("confidence", "random")
STOPS = 40  # stopping points searched for the cheapest plan to a target F1


@dataclass(frozen=True)
class ReviewCosts(Config):
    """Seconds per action and the drawing tolerance (defaults argued in docs/metrics.md)."""

    config_name = "review costs"

    look_s: float = 1.5  # glance at a whole boundary and judge it against the image (a yes/no verification)
    look_s_per_20m: float = (
        0.5  # eye travel and panning along a line, per 20 m: when looking at a boundary and when tracing one
    )
    delete_s: float = 1.0  # delete a boundary or a cut-out piece judged false (one more key)
    vertex_s: float = 1.75  # one click: a vertex drawn or moved, a cut (extreme clicking: 7 s for 4 clicks)
    find_s: float = 2.0  # find where a missing boundary starts before tracing it
    trace_tolerance_px: float = 2.0  # a drawn polyline stays this close to the true boundary
    fix_px: float = 5.0  # a run this long off the truth gets a vertex moved (one click) onto it
    cut_px: float = 20.0  # a run this long off the truth is cut out instead (a cut at each inner end, a delete)
    target_f1: float = 0.95
    assumed_metres_per_px: float = 0.152  # the ground size of a pixel when the frame has none (the paper's imagery)

    def __post_init__(self) -> None:
        values = (self.look_s, self.look_s_per_20m, self.delete_s, self.vertex_s, self.find_s, self.fix_px, self.cut_px)
        if (
            not all(np.isfinite(v) and v >= 0 for v in values)
            or not self.trace_tolerance_px > 0
            or not 0 < self.target_f1 <= 1
            or not self.assumed_metres_per_px > 0
        ):
            raise ValueError(
                "review costs must be >= 0, the tolerance and the pixel size > 0 and the target F1 in (0, 1]"
            )

    def travel_s(self, length_px: float, metres_per_px: float) -> float:
        """Eye travel along ``length_px`` of line."""
        return self.look_s_per_20m * length_px * metres_per_px / 20.0

    def look_seconds(self, length_px: float, metres_per_px: float) -> float:
        """A look at a boundary of ``length_px``."""
        return self.look_s + self.travel_s(length_px, metres_per_px)

    def draw_seconds(self, line: np.ndarray, metres_per_px: float, snapped: int = 0) -> float:
        """Drawing ``line`` by hand: find its start, click its vertices (``snapped`` ends snap onto
        a kept line for free; one click at least), follow it with the eye."""
        clicks = max(1, clicks_to_trace(line, self.trace_tolerance_px) - snapped)
        return self.find_s + clicks * self.vertex_s + self.travel_s(polyline_length(line), metres_per_px)


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


def keeps_boundary(confidence: float, line: np.ndarray, costs: ReviewCosts, metres_per_px: float) -> bool:
    """Whether a boundary belongs in the review draft: its expected saving (``confidence`` x the
    seconds to draw it) exceeds its expected cost (a look, and a delete when it is false). A
    boundary without a confidence is shown (nothing says it does not pay)."""
    if not np.isfinite(confidence):
        return True
    look = costs.look_seconds(polyline_length(line), metres_per_px)
    return bool(confidence * costs.draw_seconds(line, metres_per_px) > look + (1 - confidence) * costs.delete_s)


def review_draft(boundaries: list[Boundary], costs: ReviewCosts, metres_per_px: float) -> np.ndarray:
    """(B,) True for the boundaries the review draft shows (:func:`keeps_boundary`)."""
    return np.array([keeps_boundary(b.confidence, b.polyline, costs, metres_per_px) for b in boundaries], bool)


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
        far_all = (
            cKDTree(kept_pixels).query(np.floor(np.concatenate(samples)), k=1, distance_upper_bound=within_px)[0]
            >= within_px
        )
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
class BoundaryPlan:
    """What the reviewer does with one boundary of the draft: its ``pieces`` (pixel polylines, in
    order along it), what happens to each (``keep``, ``delete`` or ``fix``: the piece's pixels off
    the truth go) and the seconds it takes, the look included."""

    pieces: list[np.ndarray]
    actions: list[str]
    seconds: float
    false: bool  # deleted as a whole


def plan_boundary(
    line: np.ndarray, near: cKDTree | None, costs: ReviewCosts, metres_per_px: float, within_px: float = TRUE_WITHIN_PX
) -> BoundaryPlan:
    """The actions on one boundary (module docstring, step 2): its points every 1 px are on the
    truth when within ``within_px`` of a point of ``near`` (the ground truth's samples)."""
    length = polyline_length(line)
    look = costs.look_seconds(length, metres_per_px)
    pts = points_along(line, 1.0)[0]
    on = (
        near.query(pts, k=1, distance_upper_bound=within_px)[0] < within_px
        if near is not None
        else np.zeros(len(pts), bool)
    )
    if length <= 0 or on.mean() < TRUE_SHARE:
        return BoundaryPlan([line], ["delete"], look + costs.delete_s, True)
    step = length / len(pts)
    flips = np.flatnonzero(np.diff(on.astype(np.int8))) + 1
    starts, stops = np.concatenate([[0], flips]), np.concatenate([flips, [len(on)]])
    pieces, actions, seconds = [], [], look
    for a, b in zip(starts.tolist(), stops.tolist()):
        piece = polyline_between(line, a * step, b * step)
        run = (b - a) * step
        if on[a] or run < costs.fix_px:
            action = "keep"
        elif run >= costs.cut_px:
            action = "delete"
            seconds += costs.delete_s + costs.vertex_s * (int(a > 0) + int(b < len(on)))
        else:
            action = "fix"
            seconds += costs.vertex_s
        pieces.append(piece)
        actions.append(action)
    return BoundaryPlan(pieces, actions, seconds, False)


@dataclass(frozen=True)
class ReviewTrace:
    """One simulated review: seconds and F1@5 after each action, and its totals."""

    seconds: np.ndarray  # (A + 1,) cumulative, starting at 0
    f1: np.ndarray  # (A + 1,) F1@5 after each action
    look_s: float  # the first pass (the boundaries looked at and acted on)
    clicks: int

    @property
    def total_s(self) -> float:
        return float(self.seconds[-1])

    @property
    def draw_s(self) -> float:
        return self.total_s - self.look_s


def _draw(
    state: PixelState,
    samples: list[np.ndarray],
    seconds: list[float],
    f1: list[float],
    costs: ReviewCosts,
    within_px: float,
    metres_per_px: float,
    until: float = np.inf,
) -> ReviewTrace:
    """Trace the missing runs into ``state`` (changed in place), longest first, extending the
    ``seconds`` and ``f1`` of the look pass; stop once F1@5 reaches ``until``."""
    look_s, clicks = seconds[-1], 0
    for run, snapped in sorted(missing_runs(samples, state.kept_pixels(), within_px), key=lambda r: -len(r[0])):
        if f1[-1] >= until:
            break
        if (
            snapped and polyline_length(run) < costs.fix_px + 2
        ):  # a gap or stub within the eye's tolerance, as a stray shorter than fix_px
            continue
        clicks += max(1, clicks_to_trace(run, costs.trace_tolerance_px) - snapped)
        state.draw(line_pixels(run))
        seconds.append(seconds[-1] + costs.draw_seconds(run, metres_per_px, snapped))
        f1.append(state.f1())
    return ReviewTrace(np.asarray(seconds), np.asarray(f1), look_s, clicks)


def simulate_review(
    state: PixelState,
    plans: list[BoundaryPlan],
    first_piece: np.ndarray,
    samples: list[np.ndarray],
    order: np.ndarray,
    costs: ReviewCosts,
    within_px: float,
    metres_per_px: float,
    stops: int = STOPS,
) -> tuple[ReviewTrace, float]:
    """Look at every boundary of ``order`` and act on it (``plans``; its pieces are ``state``'s
    pieces from ``first_piece``), then draw: the full review's trace; and the seconds of the
    cheapest plan "look at the first k boundaries, then draw runs until F1@5 reaches the target",
    over k at ``stops`` + 1 evenly spread stopping points (NaN if no plan reaches it). ``state``
    is used up."""
    stop_at = set(np.linspace(0, len(order), stops + 1).round().astype(int).tolist())
    seconds, f1 = [0.0], [state.f1()]
    target = costs.target_f1 - 1e-12
    best = np.inf
    for i in range(len(order) + 1):
        if f1[-1] >= target:
            best = min(best, seconds[-1])
        elif (
            i in stop_at and i < len(order) and seconds[-1] < best
        ):  # a later stop has looked longer: it can only win by drawing less
            trace = _draw(state.copy(), samples, list(seconds), list(f1), costs, within_px, metres_per_px, until=target)
            hit = np.flatnonzero(trace.f1 >= target)
            best = min(best, float(trace.seconds[hit[0]])) if len(hit) else best
        if i == len(order):
            break
        b = int(order[i])
        plan = plans[b]
        for j, action in enumerate(plan.actions):
            if action != "keep":
                state.delete(int(first_piece[b]) + j, off_truth_only=action == "fix")
            if action == "fix":  # the vertex moved onto the truth: the line now runs straight across the stray
                piece = plan.pieces[j]
                state.draw(line_pixels(piece[[0, -1]]))
        seconds.append(seconds[-1] + plan.seconds)
        f1.append(state.f1())
    full = _draw(state, samples, seconds, f1, costs, within_px, metres_per_px)
    hit = np.flatnonzero(full.f1 >= target)
    best = min(best, float(full.seconds[hit[0]])) if len(hit) else best
    return full, (best if np.isfinite(best) else float("nan"))


def review_order(confidence: np.ndarray, order: str, seed: int = 0) -> np.ndarray:
    """Boundary indices in the order a reviewer looks at them: ``confidence`` least sure first
    (boundaries without a confidence last, in their order), or ``random`` (seeded)."""
    confidence = np.asarray(confidence, float)
    if order == "confidence":
        return np.argsort(np.where(np.isfinite(confidence), confidence, np.inf), kind="stable")
    if order == "random":
        return np.random.default_rng(seed).permutation(len(confidence))
    raise ValueError(f"review order must be one of {ORDERS}, got {order!r}")


def review_report(
    pred: BoundaryGraph,
    gt: BoundaryGraph,
    metres_per_px: float | None = None,
    costs: ReviewCosts = ReviewCosts(),
    seed: int = 0,
    within_px: float = TRUE_WITHIN_PX,
    curve_points: int = 21,
) -> dict:
    """The simulated review of ``pred``'s review draft against ``gt`` (one pixel frame).

    Returns minutes to a fully corrected map and from scratch, minutes to reach
    ``costs.target_f1``, each also per km of true boundary when ``metres_per_px`` is given (else
    the lengths in the costs assume ``costs.assumed_metres_per_px``), the counts of boundaries
    (in the prediction, in the draft, deleted), and the F1@5 curve against minutes
    (``curve_points`` points per order). Without a confidence on any boundary every boundary is
    in the draft and only the random order is reported (``note`` says so)."""
    mpp = metres_per_px or costs.assumed_metres_per_px
    units = graph_boundaries(pred)
    confidence = np.array([b.confidence for b in units], float)
    scored = bool(np.isfinite(confidence).any())
    shown = review_draft(units, costs, mpp) if scored else np.ones(len(units), bool)
    draft = [b for b, keep in zip(units, shown) if keep]
    gt_pixels = rasterize(flatten(gt))
    samples = boundary_samples(gt)
    near = cKDTree(np.concatenate(samples)) if samples else None
    plans = [plan_boundary(b.polyline, near, costs, mpp, within_px) for b in draft]
    first_piece = np.cumsum([0] + [len(p.pieces) for p in plans])[:-1]
    gt_length_px = float(gt.edge_lengths().sum()) if gt.n_edges else 0.0
    scratch_s = sum(costs.draw_seconds(pts, mpp) for pts in samples)
    km = gt_length_px * metres_per_px / 1000 if metres_per_px else None
    out = {
        "costs": costs.to_dict(),
        "metres_per_px": mpp,
        "metres_per_px_assumed": not metres_per_px,
        "boundaries": len(units),
        "draft_boundaries": len(draft),
        "held_back_boundaries": len(units) - len(draft),
        "held_back_px": float(sum(b.length_px for b, keep in zip(units, shown) if not keep)),
        "false_boundaries": int(sum(p.false for p in plans)),
        "cut_pieces": int(sum(p.actions.count("delete") for p in plans if not p.false)),
        "true_boundary_px": gt_length_px,
        "true_boundary_km": km,
        "scratch_minutes": scratch_s / 60,
        "scratch_clicks": sum(clicks_to_trace(pts, costs.trace_tolerance_px) for pts in samples),
        "orders": {},
    }
    if not scored:
        out["note"] = (
            "no boundary has a confidence: the draft is the whole prediction, and only the random order is reported"
        )
    # rasterised once; each order works on a copy
    draft_state = PixelState(
        [px for b, p in zip(draft, plans) for px in piece_pixels(b.polyline, p.pieces)], gt_pixels, within_px
    )
    for name in ORDERS if scored else ("random",):
        order = review_order(confidence[shown], name, seed)
        trace, to_target = simulate_review(
            draft_state.copy(), plans, first_piece, samples, order, costs, within_px, mpp
        )
        pick = np.unique(np.linspace(0, len(trace.seconds) - 1, curve_points).round().astype(int))
        out["orders"][name] = {
            "minutes": trace.total_s / 60,
            "look_minutes": trace.look_s / 60,
            "draw_minutes": trace.draw_s / 60,
            "clicks": trace.clicks,
            "start_f1": float(trace.f1[0]),
            "end_f1": float(trace.f1[-1]),
            "minutes_to_target_f1": to_target / 60,
            "curve": {"minutes": (trace.seconds[pick] / 60).tolist(), "f1": trace.f1[pick].tolist()},
        }
    if km:
        out["per_km"] = {
            "scratch_minutes": out["scratch_minutes"] / km,
            **{f"{name}_minutes": o["minutes"] / km for name, o in out["orders"].items()},
            **{f"{name}_minutes_to_target_f1": o["minutes_to_target_f1"] / km for name, o in out["orders"].items()},
        }
    return out
