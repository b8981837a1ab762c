"""Sat2Graph baseline (He et al., ECCV 2020; paper Section V-D): the graph as a 19-channel tensor.

Every pixel near a graph vertex carries the vertex's edges: channel 0 is vertexness, then six
edge slots, one per 60-degree sector around the vertex, each (existence, dx, dy). A network
predicts the tensor and a decoder turns it back into edges. As in the paper, "csBoundary's
extracted vertices serve as its vertices": the original vertex decoding is replaced by
csBoundary's keypoint FPN and vertex extraction (corner edges included), so only the edges come
from Sat2Graph, which makes the comparison one of edge prediction alone.

Encoding (:func:`encode_graph`): each pixel whose centre lies within ``radius_px`` of a vertex
belongs to the nearest such vertex (overlapping discs are split, so close vertices keep their own
pixels). A vertex's neighbours are sorted into sectors by the angle of (dx, dy) in image
coordinates (col right, row down), sector k = [60k, 60k + 60) degrees; when two share a sector the
nearer wins (the farther is usually still recovered from its own side, see below). The vector is
(neighbour - vertex) / ``max_edge_px``, clipped to [-1, 1] per component: with auxiliary keypoint
lines every 250 px, consecutive keypoints of a straight boundary differ by at most 250 px in each
coordinate, so the default loses nothing there. Decoding (:func:`decode_adjacency`): per vertex
and slot, existence and vector are averaged over the vertex's own disc pixels; if existence
exceeds ``edge_threshold`` the tip vertex + vector * ``max_edge_px`` is snapped to the nearest
other vertex within ``snap_px``. An edge counts when predicted from either end (score = the larger
probability). A clipped edge is therefore recovered only if its neighbour is within ``snap_px`` of
the clipped tip; otherwise it is lost, or it snaps to whatever vertex lies there.

Network: csBoundary's FPN trunk with 19 output channels (a fair comparison). Loss, as in
Sat2Graph: BCE on vertexness everywhere, BCE on slot existence on vertex discs, smooth-L1 on
the vectors only where the slot exists.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from csboundary.config import Config
from csboundary.data.units import MODEL_GSD
from csboundary.data.windows import PixelWindow
from csboundary.graph import BoundaryGraph
from csboundary.graph.settings import GraphSettings
from csboundary.graph.vertex_extraction import extract_vertices
from csboundary.labels.patch_graph import window_graph
from csboundary.models.afanet import edges_from_adjacency
from csboundary.models.checkpoint import load_checkpoint, load_fpn, restore_model, shipped_weights
from csboundary.models.decoding import graph_from_adjacency
from csboundary.models.fpn import FPN, FPNConfig, fpn_for_weights
from csboundary.models.maps import image_tensor, unit_bands
from csboundary.models.training.config import TrainConfig, model_config_with
from csboundary.models.training.data import TrainingCity, augment
from csboundary.models.training.loop import RunLog, TrainingRun, optimize, seed_everything

KIND = "sat2graph"
SLOTS = 6
CHANNELS = 1 + 3 * SLOTS  # vertexness, then (existence, dx, dy) per slot
EXIST = [1 + 3 * k for k in range(SLOTS)]
VECTOR = [c for k in range(SLOTS) for c in (2 + 3 * k, 3 + 3 * k)]
SECTOR = 2 * math.pi / SLOTS
VECTOR_BETA = 0.01  # smooth-L1 knee (2.5 px at 250 px): L1-like, so small offsets still get gradient


@dataclass(frozen=True)
class Sat2GraphOptions(Config):
    """Method settings, from ``TrainConfig.options`` (stored in the checkpoint, used at inference)."""

    config_name = "sat2graph"

    radius_px: float = 3.0  # vertex disc radius (pixel centres within it)
    max_edge_px: float = 250.0  # vector scale; components clipped to +-1
    snap_px: float = 15.0  # a decoded tip connects to the nearest vertex within this
    edge_threshold: float = 0.5  # mean slot existence probability for an edge
    max_degree: int | None = 2  # decoded edges per vertex (boundaries are polylines), None = no cap
    pos_weight_vertex: float = 20.0  # BCE weights of the rare positives
    pos_weight_slot: float = 2.0  # ~2 of 6 slots exist at a boundary vertex
    vector_weight: float = 1.0


# -- graph tensor ---------------------------------------------------------------------------------


def owner_map(vertices: np.ndarray, shape: tuple[int, int], radius: float) -> np.ndarray:
    """(h, w) int: the index of the nearest vertex whose disc (pixel centre within ``radius``)
    covers the pixel, -1 elsewhere. Vertices may lie outside the map (they own nothing there)."""
    h, w = shape
    owner = np.full((h, w), -1, np.int64)
    best = np.full((h, w), np.inf)
    for i, (x, y) in enumerate(np.asarray(vertices, float).reshape(-1, 2)):
        c0, c1 = max(0, math.floor(x - radius)), min(w, math.ceil(x + radius) + 1)
        r0, r1 = max(0, math.floor(y - radius)), min(h, math.ceil(y + radius) + 1)
        if c0 >= c1 or r0 >= r1:
            continue
        d = np.hypot(np.arange(c0, c1)[None] + 0.5 - x, np.arange(r0, r1)[:, None] + 0.5 - y)
        take = (d <= radius) & (d < best[r0:r1, c0:c1])
        best[r0:r1, c0:c1][take] = d[take]
        owner[r0:r1, c0:c1][take] = i
    return owner


def edge_slots(vertices: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(M, 6) int: per vertex, the neighbour in each 60-degree sector (the nearest if several), -1
    if none. Sector k holds angles atan2(dy, dx) in [60k, 60k + 60) degrees (image axes); an angle
    within 1e-9 of a sector's start belongs to that sector, so exact multiples of 60 are stable."""
    vertices = np.asarray(vertices, float).reshape(-1, 2)
    slots = np.full((len(vertices), SLOTS), -1, np.int64)
    nearest = np.full((len(vertices), SLOTS), np.inf)
    for a, b in np.asarray(edges, np.int64).reshape(-1, 2):
        for u, v in ((a, b), (b, a)):
            dx, dy = vertices[v] - vertices[u]
            length = math.hypot(dx, dy)
            if length == 0:
                continue
            k = int(math.floor((math.atan2(dy, dx) % (2 * math.pi)) / SECTOR + 1e-9)) % SLOTS
            if length < nearest[u, k]:
                nearest[u, k], slots[u, k] = length, v
    return slots


def encode_graph(
    vertices: np.ndarray, edges: np.ndarray, shape: tuple[int, int], options: Sat2GraphOptions
) -> tuple[np.ndarray, np.ndarray]:
    """The (19, h, w) float32 graph tensor of a graph in the map's pixel frame, and its loss mask.

    target[0] = 1 on vertex discs; on the disc of vertex u, for each slot k holding neighbour v:
    target[1+3k] = 1 and target[2+3k : 4+3k] = clip((v - u) / max_edge_px, -1, 1). The mask is 1
    for vertexness everywhere, for existence on every disc pixel, for the vectors only where the
    slot exists. Vertices outside the map own no pixels but are still neighbours.
    """
    vertices = np.asarray(vertices, float).reshape(-1, 2)
    owner = owner_map(vertices, shape, options.radius_px)
    target = np.zeros((CHANNELS, *shape), np.float32)
    mask = np.zeros((CHANNELS, *shape), np.float32)
    mask[0] = 1
    rows, cols = np.nonzero(owner >= 0)
    own = owner[rows, cols]
    target[0, rows, cols] = 1
    mask[1::3][:, rows, cols] = 1  # the existence channels (a view, so this writes)
    slots = edge_slots(vertices, edges)
    for k in range(SLOTS):
        nb = slots[own, k]
        has = nb >= 0
        r, c = rows[has], cols[has]
        vec = np.clip((vertices[nb[has]] - vertices[own[has]]) / options.max_edge_px, -1, 1)
        target[1 + 3 * k, r, c] = 1
        target[2 + 3 * k, r, c], target[3 + 3 * k, r, c] = vec[:, 0], vec[:, 1]
        mask[2 + 3 * k : 4 + 3 * k, r, c] = 1
    return target, mask


def decode_adjacency(vertices: np.ndarray, tensor: np.ndarray, options: Sat2GraphOptions) -> np.ndarray:
    """(M, M) symmetric edge probabilities of ``vertices`` from a (19, h, w) tensor of probabilities
    (existence) and vectors; see the module docstring. Pairs never predicted stay 0."""
    vertices = np.asarray(vertices, float).reshape(-1, 2)
    m = len(vertices)
    probs = np.zeros((m, m))
    if m < 2:
        return probs
    owner = owner_map(vertices, tensor.shape[-2:], options.radius_px).ravel()
    sel = owner >= 0
    counts = np.bincount(owner[sel], minlength=m)
    flat = tensor.reshape(CHANNELS, -1)[:, sel]
    means = np.stack([np.bincount(owner[sel], weights=flat[c], minlength=m) for c in range(1, CHANNELS)]) / np.maximum(
        counts, 1
    )
    exist = means[0::3].T  # (m, 6)
    tips = vertices[:, None] + np.stack([means[1::3].T, means[2::3].T], -1) * options.max_edge_px  # (m, 6, 2)
    dist = np.linalg.norm(tips[:, :, None] - vertices[None, None], axis=-1)  # (m, 6, m)
    dist[np.arange(m), :, np.arange(m)] = np.inf
    nearest = dist.argmin(-1)
    ok = (counts[:, None] > 0) & (exist > options.edge_threshold) & (dist.min(-1) <= options.snap_px)
    for u, k in zip(*np.nonzero(ok)):
        v = nearest[u, k]
        probs[u, v] = probs[v, u] = max(probs[u, v], exist[u, k])
    return probs


def decode_edges(
    vertices: np.ndarray, tensor: np.ndarray, options: Sat2GraphOptions, fixed=()
) -> list[tuple[int, int]]:
    """Sorted (u < v) edges decoded from ``tensor``, degree-capped like csBoundary's adjacency."""
    probs = decode_adjacency(vertices, tensor, options)
    if len(probs) < 2:
        return sorted(tuple(sorted(map(int, e))) for e in fixed)
    return edges_from_adjacency(
        torch.as_tensor(probs, dtype=torch.float32), options.edge_threshold, options.max_degree, fixed=list(fixed)
    )


def augment_with_graph(rng: np.random.Generator, vertices: np.ndarray, *arrays: np.ndarray):
    """``augment(rng, *arrays)`` plus the same flip/rotation applied to ``vertices`` (continuous
    (col, row) of the square arrays' frame). The transform is read off a grid of pixel-centre
    coordinates sent through the same call, so the graph follows the image whatever ``augment``
    drew; encoding happens afterwards, so slots and vectors are exact, never permuted channels."""
    h, w = arrays[0].shape[-2:]
    rows, cols = np.mgrid[0:h, 0:w] + 0.5
    *out, moved = augment(rng, *arrays, np.stack([cols, rows]))
    origin = moved[:, 0, 0]  # moved[:, i, j] = old centre of the pixel now at [i, j]: old = A new + b
    a = np.stack([moved[:, 0, 1] - origin, moved[:, 1, 0] - origin], axis=1)
    b = origin - a @ np.array([0.5, 0.5])
    return (np.asarray(vertices, float).reshape(-1, 2) - b) @ a, *out  # A is orthogonal: A^-1 = A^T


# -- network, loss, training ----------------------------------------------------------------------


def to_maps(logits: torch.Tensor) -> torch.Tensor:
    """(B, 19, h, w) logits -> probabilities (vertexness, existence) and vectors (tanh, in [-1, 1])."""
    is_vector = torch.zeros(CHANNELS, dtype=torch.bool, device=logits.device)
    is_vector[VECTOR] = True
    return torch.where(is_vector[:, None, None], torch.tanh(logits), torch.sigmoid(logits))


def sat2graph_loss(
    logits: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, options: Sat2GraphOptions
) -> torch.Tensor:
    """Masked means of: vertexness BCE + slot existence BCE + weighted smooth-L1 on the vectors."""

    def masked(loss, m):
        return (loss * m).sum() / m.sum().clamp(min=1)

    pw = torch.tensor(options.pos_weight_vertex, device=logits.device)
    vertex = masked(
        F.binary_cross_entropy_with_logits(logits[:, 0], target[:, 0], pos_weight=pw, reduction="none"), mask[:, 0]
    )
    pw = torch.tensor(options.pos_weight_slot, device=logits.device)
    exist = masked(
        F.binary_cross_entropy_with_logits(logits[:, EXIST], target[:, EXIST], pos_weight=pw, reduction="none"),
        mask[:, EXIST],
    )
    vector = masked(
        F.smooth_l1_loss(torch.tanh(logits[:, VECTOR]), target[:, VECTOR], beta=VECTOR_BETA, reduction="none"),
        mask[:, VECTOR],
    )
    return vertex + exist + options.vector_weight * vector


def training_sample(
    city: TrainingCity, window: PixelWindow, options: Sat2GraphOptions, rng: np.random.Generator | None = None
):
    """Image (4, s, s), target and mask (19, s, s), window-frame vertices (M, 2) and edges (E, 2).

    The graph comes from a window ``max_edge_px`` larger on each side, so a vertex near the crop's
    edge keeps its slots towards neighbours outside (as it has them in a full patch). With ``rng``
    the sample is flipped/rotated, graph first, then encoded. Pixels without imagery are masked.
    """
    margin = math.ceil(options.max_edge_px)
    context = PixelWindow(
        window.col_off - margin, window.row_off - margin, window.width + 2 * margin, window.height + 2 * margin
    )
    graph, _ = window_graph(city.labels.keypoints, city.labels.bounds, context)
    vertices = graph.vertices - margin
    read = city.mosaic.read(window)
    image, valid = unit_bands(read.data), read.valid
    if rng is not None:
        vertices, image, valid = augment_with_graph(rng, vertices, image, valid)
    target, mask = encode_graph(vertices, graph.edges, valid.shape, options)
    return image, target, mask * valid, vertices, graph.edges


def _batch(city: TrainingCity, rng: np.random.Generator, config: TrainConfig, options: Sat2GraphOptions, train: bool):
    samples = [
        training_sample(city, city.random_window(rng, config.crop), options, rng if train else None)
        for _ in range(config.batch)
    ]
    images, targets, masks = (torch.from_numpy(np.stack([s[i] for s in samples])) for i in range(3))
    return images, targets, masks, [(s[3], s[4]) for s in samples]


def _f1(tp: int, fp: int, fn: int) -> float:
    return 2 * tp / max(2 * tp + fp + fn, 1)


@torch.no_grad()
def validate(model: FPN, batches, device, options: Sat2GraphOptions) -> dict[str, float]:
    """Loss, pixel F1 of vertexness and of slot existence (on vertex discs), and F1 of the edges
    decoded on the ground-truth vertices (edges with an end owning pixels in the crop)."""
    model.eval()
    losses, counts = [], {name: np.zeros(3, np.int64) for name in ("vertex", "slot", "edge")}

    def add(name, pred, truth, where):
        counts[name] += [
            int((pred & truth & where).sum()),
            int((pred & ~truth & where).sum()),
            int((~pred & truth & where).sum()),
        ]

    for image, target, mask, graphs in batches:
        logits = model(image.to(device))
        losses.append(float(sat2graph_loss(logits, target.to(device), mask.to(device), options)))
        maps = to_maps(logits).cpu()
        add("vertex", maps[:, 0] > 0.5, target[:, 0] > 0.5, mask[:, 0] > 0)
        add("slot", maps[:, EXIST] > 0.5, target[:, EXIST] > 0.5, mask[:, EXIST] > 0)
        for tensor, (vertices, edges) in zip(maps.numpy(), graphs):
            seen = set(np.unique(owner_map(vertices, tensor.shape[-2:], options.radius_px)).tolist())
            truth = {tuple(sorted(map(int, e))) for e in edges if int(e[0]) in seen or int(e[1]) in seen}
            pred = set(decode_edges(vertices, tensor, options))
            counts["edge"] += [len(pred & truth), len(pred - truth), len(truth - pred)]
    model.train()
    return {"val_loss": float(np.mean(losses)), **{f"val_{name}_f1": _f1(*c) for name, c in counts.items()}}


def train(
    config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True
) -> Path:
    """Train the 19-channel FPN on random crops of the train city (loop and checkpoints as
    :func:`~csboundary.models.training.fpn.train_fpn`); returns the final ``sat2graph.pt``."""
    options = Sat2GraphOptions.from_dict(config.options)
    seed_everything(config.seed)
    log = RunLog(out_dir / "train.log")
    train_city = TrainingCity(config.train_city.ensure(config.cache))
    valid_city = TrainingCity(config.valid_city.ensure(config.cache))
    model_config = model_config_with(FPNConfig, {**config.fpn, "out_channels": CHANNELS})
    model = FPN(model_config).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    rng = np.random.default_rng(config.seed)
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_batches = [
        _batch(valid_city, valid_rng, config, options, train=False) for _ in range(config.validation_samples)
    ]
    run = TrainingRun(KIND, model, model_config, config, out_dir, optimizer, rng, log).resumed(resume)
    log.write(
        event="start",
        model=KIND,
        step=run.step,
        parameters=sum(p.numel() for p in model.parameters()),
        config=config.to_dict(),
    )

    def loss_at(step: int):
        image, target, mask, _ = _batch(train_city, rng, config, options, train=True)
        return sat2graph_loss(model(image.to(device)), target.to(device), mask.to(device), options), {}

    return optimize(run, loss_at, lambda step: validate(model, valid_batches, device, options), progress)


# -- inference ------------------------------------------------------------------------------------


@dataclass
class Model:
    """The city pipeline's :class:`~csboundary.models.patch_model.PatchModel`: maps are (20, S, S), channel
    0 csBoundary's keypoint probability, 1..19 the Sat2Graph tensor (averaged across overlapping
    windows like any map; its vectors are relative, so averaging is consistent)."""

    net: FPN
    keypoint_fpn: FPN
    device: torch.device
    options: Sat2GraphOptions = field(default_factory=Sat2GraphOptions)
    settings: GraphSettings = field(default_factory=GraphSettings)  # its vertices, and the city graph's steps (all off)
    confidence = None
    collect_evidence = False
    pixel_size_m = MODEL_GSD

    @classmethod
    def load(cls, path: str | Path, device: torch.device, keypoint_weights: str | Path | None = None) -> "Model":
        """A ``sat2graph`` checkpoint plus the keypoint FPN of a csBoundary bundle or ``fpn``
        checkpoint (default: the shipped bundle)."""
        payload = load_checkpoint(path, (KIND,), map_location=device)
        net = restore_model(path, KIND, payload, fpn_for_weights).to(device).eval()
        keypoint_fpn = load_fpn(keypoint_weights or shipped_weights(), device)
        return cls(net, keypoint_fpn, device, Sat2GraphOptions.from_dict(payload["train_config"].get("options", {})))

    @torch.no_grad()
    def patch_maps(self, patches: list, images: list[np.ndarray]) -> list[np.ndarray]:
        batch = image_tensor(np.stack(images), self.device)
        keypoint = torch.sigmoid(self.keypoint_fpn(batch)[:, :1])
        maps = torch.cat([keypoint, to_maps(self.net(batch))], dim=1)
        return list(maps.float().cpu().numpy())

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        """csBoundary's vertices and corner edges from the keypoint channel."""
        return extract_vertices(maps[0], self.settings.vertices)

    def connect(self, patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        """``found``'s vertices and corner edges plus the decoded Sat2Graph edges (kind ``normal``)."""
        probs = decode_adjacency(found.vertices, maps[1:], self.options)
        return graph_from_adjacency(found, probs, self.options.edge_threshold, self.options.max_degree)
