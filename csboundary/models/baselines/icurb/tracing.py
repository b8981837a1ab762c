"""Growing boundaries in one window: the traced polylines (:class:`Traces`), a batched roll-out
of the agent (with a teacher for DAgger), steps clipped to the window, and the start vertices
found on the border of a segmentation."""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage
from skimage.morphology import skeletonize

from csboundary.graph import BoundaryGraph
from csboundary.graph.polyline import segment_feet
from csboundary.models.baselines.icurb.agent import agent_input
from csboundary.models.baselines.icurb.config import ICurbConfig
from csboundary.models.baselines.icurb.geometry import inside


class Traces:
    """Polylines grown in one window: a shared vertex store and one vertex-id list per trace."""

    def __init__(self, starts: np.ndarray):
        self.points = [np.asarray(p, float) for p in starts]
        self.ids = [[i] for i in range(len(self.points))]
        self.scores: list[list[float]] = [[] for _ in self.points]
        self.done: set[int] = set()

    def history(self, i: int, k: int) -> np.ndarray:
        ids = self.ids[i][-k:]
        return np.array([self.points[ids[0]]] * (k - len(ids)) + [self.points[j] for j in ids])

    def add(self, i: int, point: np.ndarray, score: float) -> None:
        self.points.append(np.asarray(point, float))
        self.ids[i].append(len(self.points) - 1)
        self.scores[i].append(score)

    def join(self, i: int, q: np.ndarray, radius: float, score: float) -> bool:
        """If ``q`` is within ``radius`` of a traced polyline (not this trace's last two
        segments), end trace ``i`` on the foot point, splitting that segment."""
        best = None
        for u, ids in enumerate(self.ids):
            pts = np.array([self.points[j] for j in (ids[:-2] if u == i else ids)]).reshape(-1, 2)
            if len(pts) == 0:
                continue
            a, b = (pts[:-1], pts[1:]) if len(pts) > 1 else (pts, pts)
            t, foot, d = segment_feet(a, b, q)
            k = int(np.argmin(d))
            if d[k] < radius and (best is None or d[k] < best[0]):
                best = (d[k], u, k, foot[k])
        if best is None:
            return False
        _, u, k, foot = best
        ids = self.ids[u]
        head = k >= len(ids) - 2
        if len(ids) == 1 or np.linalg.norm(foot - self.points[ids[k]]) < 1:
            j = ids[k]
        elif np.linalg.norm(foot - self.points[ids[k + 1]]) < 1:
            j = ids[k + 1]
        else:
            self.points.append(foot)
            j = len(self.points) - 1
            ids.insert(k + 1, j)
            self.scores[u].insert(k + 1, self.scores[u][k])
        self.ids[i].append(j)
        self.scores[i].append(score)
        if u != i and head:
            self.done.add(u)  # two heads met: that trace ends here too
        return True

    def graph(self) -> BoundaryGraph:
        """Traced vertices (unused starts dropped) and their consecutive pairs as edges."""
        pairs = [
            (u, v, s) for ids, sc in zip(self.ids, self.scores) for (u, v), s in zip(zip(ids, ids[1:]), sc) if u != v
        ]
        used = sorted({x for u, v, _ in pairs for x in (u, v)})
        index = {j: n for n, j in enumerate(used)}
        edges = [(index[u], index[v]) for u, v, _ in pairs]
        return BoundaryGraph(
            np.array([self.points[j] for j in used]).reshape(-1, 2),
            np.array(edges, dtype=np.int64).reshape(-1, 2),
            vertex_kinds=["vertex"] * len(used),
            edge_kinds=["normal"] * len(edges),
            edge_polylines=[None] * len(edges),
            edge_scores=np.array([s for *_, s in pairs], dtype=float),
        )


def clip_step(p: np.ndarray, q: np.ndarray, box) -> tuple[np.ndarray, bool]:
    """A step p -> q kept in the box (x0, y0, x1, y1): ``q`` and False, or where p -> q leaves
    the box and True."""
    if inside(q, box)[0]:
        return q, False
    d = q - p
    limit = (
        np.where(d > 0, np.array(box[2:], float), np.array(box[:2], float)) - p
    )  # signed room to the side it heads for
    t = min([1.0] + [limit[a] / d[a] for a in range(2) if d[a] != 0])
    return p + max(t, 0.0) * d, True


@torch.no_grad()
def rollout(
    agent,
    tensor: torch.Tensor,
    starts: np.ndarray,
    config: ICurbConfig,
    teacher=None,
    beta: float = 0.0,
    rng=None,
    frame=None,
):
    """Grow a polyline from every start at once, one batched agent call per step, within
    ``frame`` (x0, y0, x1, y1; default the whole window).

    ``agent(x) -> (offsets, stop logits)``. With ``teacher(i, history) -> (target, stop)`` every
    visited state is recorded with the teacher's action, which is also taken with probability
    ``beta`` (DAgger). Returns the :class:`Traces` and the records (inputs, offsets, stops).
    """
    traces, box = Traces(starts), frame or (0, 0, tensor.shape[-1], tensor.shape[-2])
    active, records = list(range(len(traces.ids))), []
    for _ in range(config.max_steps):
        if not active:
            break
        history = np.stack([traces.history(i, max(2, config.history)) for i in active])
        x = agent_input(tensor, torch.from_numpy(history).to(tensor), config.roi)
        offsets, logits = agent(x)
        offsets, stops = offsets.cpu().numpy().astype(float), torch.sigmoid(logits).cpu().numpy()
        labels = []
        for row, i in enumerate(active):
            pos, step, stop, score = history[row, -1], offsets[row], bool(stops[row] > 0.5), float(1 - stops[row])
            if teacher is not None:
                target, t_stop = teacher(i, history[row])
                labels.append((target - pos, t_stop))
                if rng.random() < beta:
                    step, stop, score = target - pos, t_stop, 1.0
            new, left = clip_step(pos, pos + step, box)
            if np.linalg.norm(new - pos) < 0.5:
                traces.done.add(i)  # stuck (or stopped where it stands)
            elif traces.join(i, new, config.step_px / 2, score):
                traces.done.add(i)
            else:
                traces.add(i, new, score)
                if stop or left:
                    traces.done.add(i)
        if teacher is not None:
            records.append(
                (x.cpu(), np.array([o for o, _ in labels], np.float32), np.array([s for _, s in labels], np.float32))
            )
        active = [i for i in active if i not in traces.done]
    return traces, records


def border_starts(seg: np.ndarray, threshold: float, border_px: int, frame=None) -> np.ndarray:
    """(M, 2) start vertices: per connected piece of the thresholded segmentation's skeleton
    within ``border_px`` of the border of ``frame`` (x0, y0, x1, y1; default the window), its
    pixel (centre) nearest that border."""
    skeleton = skeletonize(seg > threshold)
    x0, y0, x1, y1 = frame or (0, 0, seg.shape[1], seg.shape[0])
    rows, cols = np.mgrid[0 : seg.shape[0], 0 : seg.shape[1]]
    gap = np.minimum(np.minimum(rows - y0, cols - x0), np.minimum(y1 - 1 - rows, x1 - 1 - cols))
    labels, n = ndimage.label(skeleton & (gap >= 0) & (gap < border_px), structure=np.ones((3, 3)))
    out = []
    for piece in range(1, n + 1):
        r, c = np.nonzero(labels == piece)
        k = int(np.argmin(gap[r, c]))
        out.append((c[k] + 0.5, r[k] + 0.5))
    return np.array(out, dtype=float).reshape(-1, 2)
