"""Enhanced-iCurb (Xu et al. 2021), the paper's iterative-graph-growing baseline (Section V-D).

An agent grows every road boundary vertex by vertex: from a start on the window border it looks
at an ``roi`` x ``roi`` window centred on its current vertex and predicts the next vertex (an
offset) and whether to stop. "Enhanced": besides the 4 image bands the ROI holds a segmentation
probability map, here csBoundary's own FPN (channel 1), so the baseline sees the same evidence.

Choices where the iCurb paper is not specific:

* A history channel draws the last ``history`` accepted vertices as a ~2 px polyline into the
  ROI (without it the agent cannot tell where it came from). The network is a small stride-2
  conv stack, flattened rather than pooled so the head knows where things are in the ROI.
* Expert (:class:`Expert`): project the current vertex onto the nearest ground-truth segment,
  orient the boundary to agree with the travel direction, and go ``step_px`` further along it;
  the target is cut short, with stop, where the boundary ends, leaves the window, or (a closed
  ring) comes back to the episode's start.
* Starts: at training, ground-truth crossings of the window border, heading inwards; at
  inference, where the skeleton of the thresholded segmentation meets the border (iCurb starts
  from predicted boundary ends on the image border); at a mosaic edge the imagery's edge is the
  border. Boundaries lying wholly inside a window are therefore never traced, as in iCurb.
* Tracing stops on the stop flag, on leaving the window (the vertex is clipped to the border),
  after ``max_steps``, or on coming within ``step_px / 2`` of an already traced polyline, which
  is then joined (its segment split at the foot point); when two heads meet both end.
* DAgger: an episode rolls every start of a random window out at once, taking the expert's
  action with probability beta (1 -> ``beta_min``) and the agent's otherwise, and labels every
  visited state with the expert's action. States are aggregated in a uint8 ring buffer (inputs
  are 8-bit imagery and probabilities anyway) and batches are drawn from it: MSE on offsets in
  units of roi / 2, BCE on stop (``stop_pos_weight``: about one state in 25 is a stop).
* Resume restores weights, optimizer and every random stream (``resume_run``), but the buffer
  is not checkpointed (hundreds of MB): it is rebuilt by fresh roll-outs, so a resumed run is
  not bit-identical to an uninterrupted one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import shapely
import torch
import torch.nn.functional as F
from scipy import ndimage
from shapely.geometry import LineString
from skimage.morphology import skeletonize
from torch import nn

from csboundary.config import config_from_dict
from csboundary.graph import BoundaryGraph
from csboundary.labels.boundaries import Boundary
from csboundary.labels.select import near_window
from csboundary.models.afanet import crop_rois
from csboundary.models.checkpoint import load_checkpoint, load_fpn, restore_model
from csboundary.models.fpn import FPN
from csboundary.errors import reject_unknown
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.loop import RunLog, optimize, resume_run, seed_everything
from csboundary.models.training.data import TrainingCity
from csboundary.models.maps import image_tensor, predict_mosaic_maps, predict_probabilities, unit_bands
from csboundary.models.checkpoint import shipped_weights

KIND = "icurb"
# training-only options (TrainConfig.options); the rest of the options are ICurbConfig fields
TRAIN_OPTIONS = {"window": 512, "beta_min": 0.1, "beta_decay": 0.5, "buffer": 8000, "batch": 64, "rollout_every": 2, "stop_pos_weight": 5.0}


@dataclass(frozen=True)
class ICurbConfig:
    """The agent and how it traces (stored in the checkpoint: inference needs all of it)."""

    roi: int = 64
    widths: tuple[int, ...] = (16, 32, 64, 64)  # stride-2 conv stages
    hidden: int = 256
    history: int = 5  # vertices drawn into the history channel (>= 2)
    step_px: float = 20.0
    max_steps: int = 150
    seg_threshold: float = 0.5
    border_px: int = 4  # skeleton pixels this close to the window border give start vertices

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "ICurbConfig":
        return config_from_dict(cls, data, "icurb")


def split_options(options: dict) -> tuple[ICurbConfig, dict]:
    """TrainConfig.options -> (agent config, training options); a misspelt key is an error."""
    reject_unknown(options, {*ICurbConfig.__dataclass_fields__, *TRAIN_OPTIONS}, "icurb")
    return ICurbConfig.from_dict({k: v for k, v in options.items() if k not in TRAIN_OPTIONS}), {k: options.get(k, v) for k, v in TRAIN_OPTIONS.items()}


class Agent(nn.Module):
    """(B, 6, roi, roi) ROI -> next vertex offset (B, 2) in px, within +-roi/2, and stop logit (B,)."""

    def __init__(self, config: ICurbConfig):
        super().__init__()
        layers, cin, side = [], 6, config.roi
        for w in config.widths:
            layers += [nn.Conv2d(cin, w, 3, 2, 1, bias=False), nn.BatchNorm2d(w), nn.ReLU(inplace=True)]
            cin, side = w, (side + 1) // 2
        self.body = nn.Sequential(*layers)
        self.head = nn.Sequential(nn.Flatten(), nn.Linear(cin * side * side, config.hidden), nn.ReLU(inplace=True), nn.Linear(config.hidden, 3))
        self.half = config.roi / 2

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.head(self.body(x))
        return torch.tanh(out[:, :2]) * self.half, out[:, 2]


def history_channel(history: torch.Tensor, roi: int) -> torch.Tensor:
    """(B, K, 2) vertices (last = the ROI centre) -> (B, 1, roi, roi): 1 within 1 px of their
    polyline, fading to 0 at 2 px. Pixels are placed as in ``crop_rois``."""
    rel = history - history[:, -1:]
    offsets = torch.arange(roi, device=history.device, dtype=history.dtype) - (roi - 1) / 2
    gy, gx = torch.meshgrid(offsets, offsets, indexing="ij")
    p = torch.stack([gx, gy], -1).reshape(1, -1, 1, 2)
    a, ab = rel[:, None, :-1], (rel[:, 1:] - rel[:, :-1])[:, None]
    t = (((p - a) * ab).sum(-1) / (ab * ab).sum(-1).clamp(min=1e-9)).clamp(0, 1)
    d = (p - a - t[..., None] * ab).norm(dim=-1).amin(-1)
    return (2 - d).clamp(0, 1).reshape(-1, 1, roi, roi)


def agent_input(tensor: torch.Tensor, history: torch.Tensor, roi: int) -> torch.Tensor:
    """The window tensor (5, H, W: bands, segmentation) and histories (B, K, 2) -> (B, 6, roi, roi)."""
    return torch.cat([crop_rois(tensor, history[:, -1], roi), history_channel(history, roi)], dim=1)


def _inside(points: np.ndarray, box: tuple[float, float, float, float], eps: float = 1e-6) -> np.ndarray:
    """Which points lie in the closed box (x0, y0, x1, y1)."""
    p = np.asarray(points).reshape(-1, 2)
    return (p[:, 0] >= box[0] - eps) & (p[:, 1] >= box[1] - eps) & (p[:, 0] <= box[2] + eps) & (p[:, 1] <= box[3] + eps)


def _segment_feet(a: np.ndarray, b: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot points of ``q`` on segments a->b: parameter t, foot, distance."""
    ab = b - a
    t = np.clip(((q - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    foot = a + t[:, None] * ab
    return t, foot, np.linalg.norm(q - foot, axis=-1)


class Expert:
    """The demonstrator of one window: ground-truth boundaries in window pixels, ``size`` (w, h)."""

    def __init__(self, boundaries: list[Boundary], size: tuple[int, int], step_px: float):
        self.tracks, self.box, self.step = boundaries, (0, 0, *size), float(step_px)
        self.cums = [b.cumulative for b in boundaries]
        self.a = np.concatenate([b.points[:-1] for b in boundaries] or [np.zeros((0, 2))])  # all segments a -> b
        self.b = np.concatenate([b.points[1:] for b in boundaries] or [np.zeros((0, 2))])
        self.track = np.concatenate([np.full(len(b.points) - 1, k) for k, b in enumerate(boundaries)] or [np.zeros(0, int)])
        self.s0 = np.concatenate([c[:-1] for c in self.cums] or [np.zeros(0)])  # arc length at a

    def at(self, k: int, s) -> np.ndarray:
        cum, pts = self.cums[k], self.tracks[k].points
        s = np.mod(s, cum[-1]) if self.tracks[k].closed else np.clip(s, 0, cum[-1])
        return np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=-1)

    def nearest(self, pos: np.ndarray) -> tuple[int, float, float, np.ndarray]:
        """Track, arc length and distance of the nearest ground-truth point, and its segment's direction."""
        t, _, d = _segment_feet(self.a, self.b, np.asarray(pos, float))
        j = int(np.argmin(d))
        return int(self.track[j]), float(self.s0[j] + t[j] * np.linalg.norm(self.b[j] - self.a[j])), float(d[j]), self.b[j] - self.a[j]

    def act(self, pos: np.ndarray, direction: np.ndarray, start: tuple[int, float] | None = None) -> tuple[np.ndarray, bool]:
        """The next vertex and the stop flag for a tracer at ``pos`` heading along ``direction``
        (``start``: the episode's (track, arc length), for closing rings)."""
        k, s, _, seg = self.nearest(pos)
        sign = 1.0 if np.dot(seg, direction) >= 0 else -1.0
        length, ahead, stop = self.cums[k][-1], self.step, False
        if not self.tracks[k].closed:
            room = length - s if sign > 0 else s
            if room <= ahead:
                ahead, stop = room, True
        elif start is not None and start[0] == k:
            back = ((start[1] - s) * sign) % length  # arc length ahead to the start
            if 0 < back <= ahead and length - back > self.step / 2:
                ahead, stop = back, True
        ss = s + sign * np.linspace(0, ahead, max(2, int(np.ceil(ahead / 0.5)) + 1))
        out = ~_inside(self.at(k, ss), self.box)
        if not out.any():
            return self.at(k, ss[-1]), stop
        j = int(np.argmax(out))
        if j == 0:
            return np.clip(self.at(k, ss[0]), self.box[:2], self.box[2:]), True
        lo, hi = ss[j - 1], ss[j]
        for _ in range(30):  # bisect the border crossing
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if _inside(self.at(k, mid), self.box)[0] else (lo, mid)
        return self.at(k, lo), True

    def starts(self) -> list[tuple[np.ndarray, np.ndarray, tuple[int, float]]]:
        """Every crossing of a boundary with the window border, heading inwards: (point, unit
        direction, (track, arc length))."""
        ring, out = shapely.box(*self.box).exterior, []
        for k, track in enumerate(self.tracks):
            line = LineString(track.points)
            for hit in shapely.get_parts(line.intersection(ring)):
                if hit.geom_type != "Point":
                    continue  # a piece running along the border
                s = line.project(hit)
                for sign in (1.0, -1.0):
                    ahead = self.at(k, s + sign)
                    if _inside(ahead, self.box, eps=-1e-3)[0]:
                        point = self.at(k, s)
                        out.append((point, (ahead - point) / max(np.linalg.norm(ahead - point), 1e-9), (k, s)))
                        break
        return out

    def teacher(self, starts):
        """``act`` as the roll-out's teacher: the travel direction is the last step taken (the
        start's own direction before the first step)."""
        def action(i: int, history: np.ndarray) -> tuple[np.ndarray, bool]:
            d = history[-1] - history[-2]
            return self.act(history[-1], d if np.linalg.norm(d) > 1e-6 else starts[i][1], starts[i][2])
        return action


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
            t, foot, d = _segment_feet(a, b, q)
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
        pairs = [(u, v, s) for ids, sc in zip(self.ids, self.scores) for (u, v), s in zip(zip(ids, ids[1:]), sc) if u != v]
        used = sorted({x for u, v, _ in pairs for x in (u, v)})
        index = {j: n for n, j in enumerate(used)}
        edges = [(index[u], index[v]) for u, v, _ in pairs]
        return BoundaryGraph(np.array([self.points[j] for j in used]).reshape(-1, 2), np.array(edges, dtype=np.int64).reshape(-1, 2),
                             vertex_kinds=["vertex"] * len(used), edge_kinds=["normal"] * len(edges), edge_polylines=[None] * len(edges),
                             edge_scores=np.array([s for *_, s in pairs], dtype=float))


def _clip(p: np.ndarray, q: np.ndarray, box) -> tuple[np.ndarray, bool]:
    """``q``, or where p -> q leaves the box (x0, y0, x1, y1) and True."""
    if _inside(q, box)[0]:
        return q, False
    d = q - p
    limit = np.where(d > 0, np.array(box[2:], float), np.array(box[:2], float)) - p  # signed room to the side it heads for
    t = min([1.0] + [limit[a] / d[a] for a in range(2) if d[a] != 0])
    return p + max(t, 0.0) * d, True


@torch.no_grad()
def rollout(agent, tensor: torch.Tensor, starts: np.ndarray, config: ICurbConfig, teacher=None, beta: float = 0.0, rng=None, frame=None):
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
            new, left = _clip(pos, pos + step, box)
            if np.linalg.norm(new - pos) < 0.5:
                traces.done.add(i)  # stuck (or stopped where it stands)
            elif traces.join(i, new, config.step_px / 2, score):
                traces.done.add(i)
            else:
                traces.add(i, new, score)
                if stop or left:
                    traces.done.add(i)
        if teacher is not None:
            records.append((x.cpu(), np.array([o for o, _ in labels], np.float32), np.array([s for _, s in labels], np.float32)))
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


def _load_fpn(path: str | Path | None, device: torch.device) -> FPN:
    """csBoundary's FPN from an ``fpn`` checkpoint or a bundle (default: the shipped bundle)."""
    return load_fpn(path or shipped_weights(), device)


class Model:
    """Enhanced-iCurb as a :class:`~csboundary.pipeline.city.PatchModel`."""

    def __init__(self, agent: Agent, config: ICurbConfig, fpn: FPN, device: torch.device):
        self.agent, self.config, self.fpn, self.device = agent.eval(), config, fpn, device

    @classmethod
    def load(cls, path: str | Path, device: torch.device, seg_weights: str | Path | None = None) -> "Model":
        """The agent of an ``icurb`` checkpoint plus the FPN ``seg_weights`` (default: the one it
        was trained with, else the shipped bundle)."""
        payload = load_checkpoint(path, (KIND,), map_location=device)
        agent = restore_model(path, KIND, payload, lambda c: Agent(ICurbConfig.from_dict(c))).to(device)
        config = ICurbConfig.from_dict(payload[f"{KIND}_config"])
        return cls(agent, config, _load_fpn(seg_weights or payload["train_config"].get("fpn_weights") or None, device), device)

    def patch_maps(self, patches: list, images: list[np.ndarray]) -> list[np.ndarray]:
        """(1, S, S) segmentation probability per patch (the FPN's channel 1)."""
        return [p[1:2] for p in predict_probabilities(self.fpn, np.stack(images), self.device)]

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        starts = border_starts(maps[0], self.config.seg_threshold, self.config.border_px)
        return BoundaryGraph(starts, vertex_kinds=["start"] * len(starts))

    @torch.no_grad()
    def connect(self, patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        """Trace from ``found``'s starts. Where the window reaches beyond the imagery (a mosaic
        edge: zero padding), the imagery's edge is the border instead: the starts are taken
        again on it and tracing stops there."""
        has = image.any(axis=0)
        rows, cols = np.flatnonzero(has.any(axis=1)), np.flatnonzero(has.any(axis=0))
        if len(rows) == 0:
            return Traces(np.zeros((0, 2))).graph()
        frame = (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
        starts = found.vertices
        if frame != (0, 0, image.shape[2], image.shape[1]):
            starts = border_starts(maps[0], self.config.seg_threshold, self.config.border_px, frame)
        seg = torch.from_numpy(np.ascontiguousarray(maps[:1], dtype=np.float32)).to(self.device)
        tensor = torch.cat([image_tensor(image, self.device), seg])
        return rollout(self.agent, tensor, starts, self.config, frame=frame)[0].graph()


# -- training -----------------------------------------------------------------------------------------


class ReplayBuffer:
    """Aggregated DAgger states in a ring: inputs as uint8, expert offsets and stops."""

    def __init__(self, capacity: int, roi: int):
        self.x = torch.zeros((capacity, 6, roi, roi), dtype=torch.uint8)
        self.offset, self.stop = np.zeros((capacity, 2), np.float32), np.zeros(capacity, np.float32)
        self.size = self.head = 0

    def add(self, x: torch.Tensor, offset: np.ndarray, stop: np.ndarray) -> None:
        index = (self.head + np.arange(len(x))) % len(self.x)
        self.x[torch.from_numpy(index)] = (x.cpu() * 255).round().clamp(0, 255).to(torch.uint8)
        self.offset[index], self.stop[index] = offset, stop
        self.head = int(index[-1] + 1) % len(self.x) if len(x) else self.head
        self.size = min(self.size + len(x), len(self.x))

    def batch(self, index: np.ndarray, device: torch.device):
        return (self.x[torch.from_numpy(index)].to(device).float() / 255, torch.from_numpy(self.offset[index]).to(device),
                torch.from_numpy(self.stop[index]).to(device))


def _window_data(city: TrainingCity, window, config: ICurbConfig, device: torch.device):
    """The window's tensor (bands, FPN segmentation) and its expert."""
    seg = np.zeros((1, window.height, window.width), np.float32)
    part = window.intersection(city.mosaic.window)
    if part is not None:
        (rows, cols), (lrows, lcols) = part.slices(), part.relative_to(window).slices()
        seg[0, lrows, lcols] = city.maps[rows, cols]
    tensor = torch.from_numpy(np.concatenate([unit_bands(city.mosaic.read(window).data), seg])).to(device)
    offset = np.array([window.col_off, window.row_off], float)
    tracks = [Boundary(city.labels.boundaries[k].points - offset, city.labels.boundaries[k].closed)
              for k in near_window(city.labels.bounds, window, pad=config.step_px)]
    return tensor, Expert(tracks, (window.width, window.height), config.step_px)


def _imitation_loss(agent: Agent, x, offset, stop, stop_pos_weight: float) -> torch.Tensor:
    pred, logit = agent(x)
    target = (offset / agent.half).clamp(-1, 1)
    weight = torch.tensor(stop_pos_weight, device=x.device)
    return F.mse_loss(pred / agent.half, target) + F.binary_cross_entropy_with_logits(logit, stop, pos_weight=weight)


@torch.no_grad()
def validate(agent: Agent, city: TrainingCity, windows, config: ICurbConfig, opts: dict, device) -> dict[str, float]:
    """Pure agent roll-outs (beta = 0) from the ground-truth starts of fixed valid windows: the
    loss and the offset error against the expert on the visited states, and the drift (mean
    distance of the traced vertices to the ground truth)."""
    agent.eval()
    losses, errors, drift = [], [], []
    for window in windows:
        tensor, expert = _window_data(city, window, config, device)
        if starts := expert.starts():
            traces, records = rollout(agent, tensor, np.array([s[0] for s in starts]), config, expert.teacher(starts), 0.0, np.random.default_rng(0))
            for x, offset, stop in records:
                x, offset, stop = x.to(device), torch.from_numpy(offset).to(device), torch.from_numpy(stop).to(device)
                losses.append(float(_imitation_loss(agent, x, offset, stop, opts["stop_pos_weight"])))
                errors += (agent(x)[0] - offset).norm(dim=1).tolist()
            drift += [expert.nearest(p)[2] for p in traces.points]
    return {f"val_{k}": float(np.mean(v)) if v else float("nan") for k, v in (("loss", losses), ("offset_px", errors), ("drift_px", drift))}


def train(config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True) -> Path:
    """DAgger imitation of the expert on the train city (see the module docstring)."""
    seed_everything(config.seed)
    out_dir = Path(out_dir)
    log = RunLog(out_dir / "train.log")
    model_config, opts = split_options(config.options)
    fpn = _load_fpn(config.fpn_weights or None, device)
    cities = {}
    for name, spec in (("train", config.train_city), ("valid", config.valid_city)):
        city = TrainingCity(spec.ensure(config.cache))
        city.maps = predict_mosaic_maps(fpn, city.mosaic, city.labels.grid, device, progress)[1].copy()  # segmentation only
        cities[name] = city
    del fpn
    agent = Agent(model_config).to(device)
    optimizer = torch.optim.Adam(agent.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_windows = [cities["valid"].random_window(valid_rng, opts["window"]) for _ in range(config.validation_samples)]
    rng = np.random.default_rng(config.seed)
    step, history = resume_run(resume, KIND, agent, optimizer, rng)
    buffer = ReplayBuffer(opts["buffer"], model_config.roi)  # not checkpointed: rebuilt after a resume
    log.write(event="start", model=KIND, step=step, parameters=sum(p.numel() for p in agent.parameters()), config=config.to_dict())

    def loss_at(step: int):
        beta = max(opts["beta_min"], 1 - (1 - opts["beta_min"]) * step / max(1.0, opts["beta_decay"] * config.steps))
        for attempt in range(200):
            if buffer.size >= opts["batch"] and (attempt > 0 or step % opts["rollout_every"]):
                break
            tensor, expert = _window_data(cities["train"], cities["train"].random_window(rng, opts["window"]), model_config, device)
            starts = expert.starts()
            if starts:
                agent.eval()
                _, records = rollout(agent, tensor, np.array([s[0] for s in starts]), model_config, expert.teacher(starts), beta, rng)
                for record in records:
                    buffer.add(*record)
        else:
            raise RuntimeError("no ground-truth boundary crosses the training windows")
        agent.train()
        x, offset, stop = buffer.batch(rng.integers(0, buffer.size, opts["batch"]), device)
        return _imitation_loss(agent, x, offset, stop, opts["stop_pos_weight"]), {"beta": beta, "buffer": buffer.size}

    return optimize(KIND, agent, model_config, config, out_dir, optimizer, rng, step, history, log, loss_at,
                    lambda step: validate(agent, cities["valid"], valid_windows, model_config, opts, device), progress)
