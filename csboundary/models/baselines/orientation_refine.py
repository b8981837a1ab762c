"""OrientationRefine baseline (Batra et al., CVPR 2019; paper Section V-D): the segmentation family.

Stage 1 predicts the boundary segmentation jointly with its orientation (the two tasks share a
trunk, so the orientation task teaches the segmentation about connectivity). Stage 2, the
refinement network, takes the image and a segmentation and outputs a corrected one; as in the
paper it learns from *corrupted* ground truth (gaps cut into the boundaries, false blobs added),
half the time from stage 1's own output. At inference: stage 1 -> stage 2 -> threshold ->
skeleton -> graph (:mod:`csboundary.graph.skeleton_graph`).

Choices the original leaves to the task: orientation is undirected here (a road boundary has no
travel direction; the label's sign follows the ground truth's vertex order, which the image
cannot show), in ``bins`` classes over 180 degrees, supervised on boundary pixels only; both
networks are csBoundary's FPN trunk (stage 2 narrower, with 5 input channels), for a fair
comparison; stage 2 gets the last ``refine_fraction`` of the steps.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from csboundary.config import Config
from csboundary.data.units import MODEL_GSD
from csboundary.graph import BoundaryGraph
from csboundary.graph.settings import GraphSettings
from csboundary.graph.skeleton_graph import SkeletonConfig, skeleton_graph
from csboundary.labels.rasterize import orientation_label
from csboundary.models.checkpoint import load_checkpoint, restore_model
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.maps import image_tensor
from csboundary.models.training.config import TrainConfig, model_config_with
from csboundary.models.training.data import TrainingCity
from csboundary.models.training.loop import RunLog, TrainingRun, optimize, seed_everything

KIND = "orientation-refine"
IGNORE = -100


@dataclass
class Options(Config):
    config_name = "orientation-refine"

    bins: int = 16  # orientation classes over 180 degrees
    pos_weight: float = 10.0  # BCE weight of boundary pixels (about 3 % of a crop)
    orientation_weight: float = 0.5
    refine_fraction: float = 0.3  # share of the steps spent on stage 2
    refiner: dict = field(default_factory=lambda: {"widths": [16, 24, 32, 48], "pyramid": 24, "stem": 16})
    skeleton: dict = field(default_factory=dict)  # SkeletonConfig overrides


# -- labels ---------------------------------------------------------------------------------------


def orientation_classes(vectors: np.ndarray, boundary: np.ndarray, bins: int) -> np.ndarray:
    """(h, w) int64 class of the undirected direction of (2, h, w) (d col, d row) vectors on
    boundary pixels, ``IGNORE`` elsewhere; class k covers [k, k + 1) * 180 / bins degrees."""
    angle = np.arctan2(-vectors[1], vectors[0]) % math.pi
    classes = np.minimum((angle / (math.pi / bins)).astype(np.int64), bins - 1)
    return np.where(boundary, classes, IGNORE)


def augment_with_vectors(rng: np.random.Generator, vectors: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """The random rotation / flip of :func:`~csboundary.models.training.data.augment` applied to
    (2, h, w) direction vectors too: their positions move and their components turn with them."""
    k = int(rng.integers(4))
    flip = bool(rng.integers(2))
    out = []
    for a in (vectors, *arrays):
        a = np.rot90(a, k, axes=(-2, -1))
        out.append(a[..., ::-1] if flip else a)
    dc, dr = out[0]
    for _ in range(k):  # np.rot90 maps (col, row) -> (row, W - 1 - col): a step (dc, dr) -> (dr, -dc)
        dc, dr = dr, -dc
    if flip:
        dc = -dc
    out[0] = np.stack([dc, dr])
    return [np.ascontiguousarray(a) for a in out]


def corrupt(segmentation: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A ground-truth segmentation with what stage 1 gets wrong: gaps, false blobs, blur."""
    out = segmentation.astype(np.float32).copy()
    on = np.argwhere(out > 0.5)
    for _ in range(int(rng.integers(1, 6))):
        if len(on):
            r, c = on[rng.integers(len(on))]
            cv2.circle(out, (int(c), int(r)), int(rng.integers(5, 20)), 0.0, -1)
    h, w = out.shape
    for _ in range(int(rng.integers(0, 3))):
        p0 = rng.integers(0, [w, h])
        p1 = p0 + rng.integers(-40, 40, 2)
        cv2.line(out, tuple(int(v) for v in p0), tuple(int(v) for v in p1), float(rng.uniform(0.5, 1)), 3)
    return cv2.GaussianBlur(out, (5, 5), 1.0)


def _sample(city: TrainingCity, window, options: Options, rng: np.random.Generator, train: bool):
    image, target, valid = city.fpn_sample(window)
    lab = city.labels
    vectors, _ = orientation_label(lab.boundaries, lab.bounds, window, city.config.segmentation_width)
    seg = target[1]
    if train:
        vectors, image, seg, valid = augment_with_vectors(rng, vectors, image, seg, valid)
    return image, seg, orientation_classes(vectors, seg > 0.5, options.bins), valid


def _batch(city, rng, config: TrainConfig, options: Options, train: bool):
    parts = [_sample(city, city.random_window(rng, config.crop), options, rng, train) for _ in range(config.batch)]
    return [torch.from_numpy(np.stack(p)) for p in zip(*parts)]


# -- losses, validation ------------------------------------------------------------------------------


def _seg_loss(logit: torch.Tensor, seg: torch.Tensor, valid: torch.Tensor, pos_weight: float) -> torch.Tensor:
    loss = F.binary_cross_entropy_with_logits(
        logit, seg, pos_weight=torch.tensor(pos_weight, device=logit.device), reduction="none"
    )
    mask = valid.to(loss.dtype)
    return (loss * mask).sum() / mask.sum().clamp(min=1)


def stage1_loss(out: torch.Tensor, seg, orient, valid, options: Options) -> torch.Tensor:
    ce = F.cross_entropy(out[:, 1:], orient, ignore_index=IGNORE) if (orient != IGNORE).any() else out.sum() * 0
    return _seg_loss(out[:, 0], seg, valid, options.pos_weight) + options.orientation_weight * ce


def _f1(pred: torch.Tensor, truth: torch.Tensor, valid: torch.Tensor) -> float:
    tp = int((pred & truth & valid).sum())
    fp = int((pred & ~truth & valid).sum())
    fn = int((~pred & truth & valid).sum())
    return 2 * tp / max(2 * tp + fp + fn, 1)


@torch.no_grad()
def validate(stage1: FPN, refiner: FPN | None, batches, device) -> dict[str, float]:
    stage1.eval()
    f1_1, f1_2, acc = [], [], []
    for image, seg, orient, valid in batches:
        out = stage1(image.to(device))
        prob = torch.sigmoid(out[:, :1])
        truth = (seg > 0.5).to(device)
        f1_1.append(_f1(prob[:, 0] > 0.5, truth, valid.to(device)))
        known = orient.to(device) != IGNORE
        acc.append(
            float((out[:, 1:].argmax(1)[known] == orient.to(device)[known]).float().mean()) if known.any() else 0.0
        )
        if refiner is not None:
            refiner.eval()
            refined = torch.sigmoid(refiner(torch.cat([image.to(device), prob], 1)))[:, 0]
            f1_2.append(_f1(refined > 0.5, truth, valid.to(device)))
            refiner.train()
    stage1.train()
    metrics = {"val_seg_f1": float(np.mean(f1_1)), "val_orientation_accuracy": float(np.mean(acc))}
    if f1_2:
        metrics["val_refined_seg_f1"] = float(np.mean(f1_2))
    return metrics


# -- training ---------------------------------------------------------------------------------------


def train(
    config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True
) -> Path:
    """Stage 1 for the first (1 - refine_fraction) of the steps, then stage 2 on its outputs and on
    corrupted ground truth. One checkpoint holds both networks (kind ``orientation-refine``)."""
    options = Options.from_dict(config.options)
    seed_everything(config.seed)
    log = RunLog(out_dir / "train.log")
    train_city = TrainingCity(config.train_city.ensure(config.cache))
    valid_city = TrainingCity(config.valid_city.ensure(config.cache))
    model = _Pair(options, model_config_with(FPNConfig, {**config.fpn, "out_channels": 1 + options.bins})).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    rng = np.random.default_rng(config.seed)
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_batches = [_batch(valid_city, valid_rng, config, options, False) for _ in range(config.validation_samples)]
    run = TrainingRun(KIND, model, model.config, config, out_dir, optimizer, rng, log).resumed(resume)
    stage2_from = round(config.steps * (1 - options.refine_fraction))
    log.write(
        event="start",
        model=KIND,
        step=run.step,
        parameters=sum(p.numel() for p in model.parameters()),
        config=config.to_dict(),
    )

    def loss_at(step: int):
        image, seg, orient, valid = (t.to(device) for t in _batch(train_city, rng, config, options, True))
        if step < stage2_from:
            return stage1_loss(model.stage1(image), seg, orient, valid, options), {"stage": 1}
        with torch.no_grad():
            predicted = torch.sigmoid(model.stage1(image)[:, :1])
        corrupted = torch.from_numpy(np.stack([corrupt(s, rng) for s in seg.cpu().numpy()]))[:, None].to(device)
        use_own = torch.from_numpy(rng.random(len(seg)) < 0.5).to(device).view(-1, 1, 1, 1)
        hint = torch.where(use_own, predicted, corrupted)
        return _seg_loss(model.refiner(torch.cat([image, hint], 1))[:, 0], seg, valid, options.pos_weight), {"stage": 2}

    def check(step: int) -> dict:  # the refiner is judged once it has been trained
        return validate(model.stage1, model.refiner if step > stage2_from else None, valid_batches, device)

    return optimize(run, loss_at, check, progress)


@dataclass
class _PairConfig(Config):
    stage1: dict
    refiner: dict
    options: dict


class _Pair(torch.nn.Module):
    """Both networks in one module, so one optimizer, checkpoint and resume serve the two stages."""

    def __init__(self, options: Options, stage1_config: FPNConfig):
        super().__init__()
        refiner_config = FPNConfig.from_dict({**options.refiner, "in_channels": 5, "out_channels": 1})
        self.stage1 = FPN(stage1_config)
        self.refiner = FPN(refiner_config)
        self.config = _PairConfig(stage1_config.to_dict(), refiner_config.to_dict(), asdict(options))

    @classmethod
    def from_config(cls, data: dict) -> "_Pair":
        return cls(Options.from_dict(data["options"]), FPNConfig.from_dict(data["stage1"]))


# -- inference ----------------------------------------------------------------------------------------


class Model:
    """OrientationRefine behind the city pipeline's ``PatchModel`` steps: maps = the refined
    segmentation probability; the graph = its skeleton."""

    settings = GraphSettings()  # the city graph's steps all off
    confidence = None
    collect_evidence = False
    pixel_size_m = MODEL_GSD

    def __init__(self, pair: _Pair, device: torch.device):
        self.pair, self.device = pair.eval(), device
        self.skeleton = SkeletonConfig(**pair.config.options.get("skeleton", {}))

    @classmethod
    def load(cls, path: str | Path, device: torch.device) -> "Model":
        payload = load_checkpoint(path, (KIND,), map_location=device)
        pair = restore_model(path, KIND, payload, _Pair.from_config).to(device)
        return cls(pair, device)

    @torch.no_grad()
    def patch_maps(self, patches: list, images: list[np.ndarray]) -> list[np.ndarray]:
        image = torch.stack([image_tensor(i, self.device) for i in images])
        seg = torch.sigmoid(self.pair.stage1(image)[:, :1])
        refined = torch.sigmoid(self.pair.refiner(torch.cat([image, seg], 1)))
        return list(refined.float().cpu().numpy())

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        return skeleton_graph(maps[0], self.skeleton)

    def connect(self, patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        return found
