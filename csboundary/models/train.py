"""Training loops for the FPN and AfANet (paper V-B), nanoGPT-style: one file, plain loops.

FPN: random crops of the train city, Adam (paper: lr 1e-3, decay 1e-4), BCE on the keypoint
heat and the segmentation with ``pos_weight`` against class imbalance (boundary pixels are ~3%
of a crop, keypoint peaks far fewer). AfANet: "we first pre-train the network with ground-truth
graph vertices, and then train AfANet with the graph vertices extracted from predicted keypoint
maps": stage ``gt`` then stage ``pred``, BCE on the adjacency label of each vertex set, positives
weighted by the negative/positive ratio (capped). Seeded; validation every N steps on the valid
city; checkpoints hold config, code version and validation metrics and resume exactly.
"""

from __future__ import annotations

import json
import math
import random
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from csboundary.config import config_from_dict
from csboundary.data import city as layout
from csboundary.errors import InputError
from csboundary.graph.crossings import CrossingConfig, added_crossings
from csboundary.graph.vertex_extraction import VertexConfig, extract_vertices
from csboundary.models.afanet import AfANet, AfANetConfig, edges_from_adjacency
from csboundary.models.checkpoint import code_version, load_checkpoint, load_fpn, save_checkpoint
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.augmentation import AugmentConfig, photometric
from csboundary.models.training_data import CitySpec, TrainingCity, WorldsConfig
from csboundary.models.maps import predict_mosaic_maps


@dataclass
class TrainConfig:
    """Everything a run depends on; stored in every checkpoint and in the log."""

    model: str = "fpn"  # fpn | afanet
    seed: int = 0
    cache: str = "data/cities"
    train_city: CitySpec | None = field(default_factory=CitySpec)  # null: train on ``worlds`` (and extra cities) only
    worlds: dict = field(default_factory=dict)  # WorldsConfig: many fresh cities of a style mix; {} = none
    valid_city: CitySpec = field(default_factory=lambda: CitySpec(split="valid", seed=0, tiles=(1, 1)))
    steps: int = 2500
    lr: float = 1e-3
    weight_decay: float = 1e-4
    validate_every: int = 250
    validation_samples: int = 8
    extra_train_cities: list = field(default_factory=list)  # city directories (imported, from masks, a user's own) trained on beside train_city
    augment: dict = field(default_factory=lambda: {"enabled": False})  # AugmentConfig overrides; {} = every augmentation at its defaults
    snapshots: bool = False  # also keep <kind>-step<N>.pt (weights only) at every validation, for selecting a model on other data
    encoder_lr_scale: float = 1.0  # pretrained FPN encoder: its learning rate relative to lr (a small one keeps ImageNet features)
    freeze_encoder_bn: bool = False  # pretrained FPN encoder: keep its batch-norm statistics (ImageNet's, not the synthetic cities')
    autocast_bf16: bool = False  # bfloat16 autocast of forward passes (CPUs with AVX-512 BF16, GPUs); float32 when false
    # fpn
    fpn: dict = field(default_factory=dict)  # FPNConfig overrides
    crop: int = 256
    batch: int = 4
    pos_weight_keypoint: float = 20.0
    pos_weight_segmentation: float = 10.0
    # afanet
    afanet: dict = field(default_factory=dict)  # AfANetConfig overrides
    fpn_weights: str = ""  # the trained FPN whose maps and vertices AfANet learns from
    window: int = 1100  # AfANet trains on whole expanded-patch-sized windows, as it infers
    gt_steps: int = 600  # stage 1 (ground-truth vertices); the rest of ``steps`` is stage 2
    vertex_jitter_px: float = 1.0  # noise on ground-truth vertices in stage 1
    crossing_spacing_px: int = 0  # AfANet stage 2: also the FPN segmentation's grid-crossing vertices (csboundary.graph.crossings)
    max_vertices: int = 160
    max_pos_weight: float = 30.0
    # baselines (csboundary.models.baselines): method-specific settings, documented per method
    options: dict = field(default_factory=dict)

    @classmethod
    def from_file(cls, path: str | Path) -> "TrainConfig":
        data = json.loads(Path(path).read_text())
        return cls.from_dict(data)

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        return config_from_dict(cls, data, "training", nested={"train_city": CitySpec, "valid_city": CitySpec})

    def to_dict(self) -> dict:
        return asdict(self)


def fpn_parameter_groups(model, config: TrainConfig) -> list[dict]:
    """Optimizer groups: a pretrained encoder at ``encoder_lr_scale`` of the rate, the rest at 1
    (``lr_scale`` is read by the schedule); sets the encoder's batch-norm freeze."""
    encoder = getattr(model, "encoder", None)
    if encoder is None:
        return [{"params": list(model.parameters()), "lr_scale": 1.0}]
    model.freeze_encoder_bn = config.freeze_encoder_bn
    inside = {id(p) for p in encoder.parameters()}
    return [{"params": list(encoder.parameters()), "lr_scale": config.encoder_lr_scale},
            {"params": [p for p in model.parameters() if id(p) not in inside], "lr_scale": 1.0}]


def training_pixel_size(config: dict) -> float | None:
    """The pixel size in metres of the cities a (recorded) training config trained on, read from
    their ``city.json`` without building anything; None when none is on disk or they disagree."""
    try:
        cfg = TrainConfig.from_dict(config)
    except (TypeError, ValueError):
        return None
    paths = [cfg.train_city.path(cfg.cache)] if cfg.train_city is not None else []
    if cfg.worlds:
        paths += [spec.path(cfg.cache) for spec in WorldsConfig.from_dict(cfg.worlds).specs()]
    sizes = set()
    for path in [*paths, *map(Path, cfg.extra_train_cities)]:
        if layout.is_city_dir(path):
            gsd = layout.read_meta(path).get("gsd")
            if isinstance(gsd, (int, float)):
                sizes.add(round(float(gsd), 6))
    return sizes.pop() if len(sizes) == 1 else None


def training_cities(config: TrainConfig) -> list[TrainingCity]:
    """The synthetic ``train_city`` and ``worlds`` cities (built on first use) and every
    ``extra_train_cities`` directory."""
    specs = [config.train_city] if config.train_city is not None else []
    if config.worlds:
        specs += WorldsConfig.from_dict(config.worlds).specs()
    if not specs and not config.extra_train_cities:
        raise ValueError("the training config names no training city (train_city, worlds or extra_train_cities)")
    paths = [spec.ensure(config.cache, progress=len(specs) == 1) for spec in specs] + list(config.extra_train_cities)
    for path in config.extra_train_cities:
        if not layout.is_city_dir(path):
            raise InputError(path, "not a city directory (tiles/, ground_truth.gpkg and city.json; see csboundary import-masks)")
    return [TrainingCity(p) for p in paths]


def autocast(config: TrainConfig, device: torch.device):
    """bfloat16 autocast when the config asks for it, else a no-op context."""
    return torch.autocast(device.type, dtype=torch.bfloat16, enabled=config.autocast_bf16)


_RUN_CODE_VERSION: dict[str, str] = {}


def seed_everything(seed: int) -> None:
    """Seed every random stream and stamp the code version of the run's start (provenance:
    the code that trained the weights, not the code around when they were saved)."""
    _RUN_CODE_VERSION["at_start"] = code_version()
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


class RunLog:
    """Append-only JSON-lines log (one line per validation and per milestone) plus stdout."""

    def __init__(self, path: Path):
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)

    def write(self, **record: Any) -> None:
        record = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), **record}
        with open(self.path, "a") as fh:
            fh.write(json.dumps(record) + "\n")
        tqdm.write(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in record.items()))


# -- FPN ----------------------------------------------------------------------------------------------


def fpn_loss(logits: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, config: TrainConfig) -> torch.Tensor:
    weights = torch.tensor([config.pos_weight_keypoint, config.pos_weight_segmentation], device=logits.device).view(1, 2, 1, 1)
    loss = F.binary_cross_entropy_with_logits(logits, target, pos_weight=weights, reduction="none")
    mask = valid[:, None].to(loss.dtype)
    return (loss * mask).sum() / (mask.sum() * 2).clamp(min=1)


def _fpn_batch(cities: list[TrainingCity], rng: np.random.Generator, config: TrainConfig, augmentation: AugmentConfig | None):
    """``config.batch`` samples, each from a city drawn in proportion to its area; augmented
    (:mod:`csboundary.models.augmentation`) when ``augmentation`` is given (training), as they are
    otherwise (validation)."""
    areas = np.array([c.mosaic.width * c.mosaic.height for c in cities], float)
    images, targets, valids = [], [], []
    for _ in range(config.batch):
        city = cities[int(rng.choice(len(cities), p=areas / areas.sum()))] if len(cities) > 1 else cities[0]
        if augmentation is not None:
            image, target, valid = city.augmented_fpn_sample(rng, config.crop, augmentation)
        else:
            image, target, valid = city.fpn_sample(city.random_window(rng, config.crop))
        images.append(image)
        targets.append(target)
        valids.append(valid)
    return torch.from_numpy(np.stack(images)), torch.from_numpy(np.stack(targets)), torch.from_numpy(np.stack(valids))


@torch.no_grad()
def validate_fpn(model: FPN, batches, device, config: TrainConfig) -> dict[str, float]:
    model.eval()
    losses, tp, fp, fn = [], 0, 0, 0
    for image, target, valid in batches:
        logits = model(image.to(device))
        losses.append(float(fpn_loss(logits, target.to(device), valid.to(device), config)))
        pred = (torch.sigmoid(logits[:, 1]) > 0.5).cpu() & valid
        truth = (target[:, 1] > 0.5) & valid
        tp += int((pred & truth).sum())
        fp += int((pred & ~truth).sum())
        fn += int((~pred & truth).sum())
    model.train()
    precision, recall = tp / max(tp + fp, 1), tp / max(tp + fn, 1)
    return {"val_loss": float(np.mean(losses)), "val_seg_precision": precision, "val_seg_recall": recall,
            "val_seg_f1": 2 * precision * recall / max(precision + recall, 1e-9)}


def train_fpn(config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True) -> Path:
    seed_everything(config.seed)
    log = RunLog(out_dir / "train.log")
    train_cities = training_cities(config)
    valid_city = TrainingCity(config.valid_city.ensure(config.cache))
    model_config = _model_config(FPNConfig, config.fpn)
    model = FPN(model_config).to(device)
    optimizer = torch.optim.Adam(fpn_parameter_groups(model, config), lr=config.lr, weight_decay=config.weight_decay)
    rng = np.random.default_rng(config.seed)
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_batches = [_fpn_batch([valid_city], valid_rng, config, None) for _ in range(config.validation_samples)]
    augmentation = _model_config(AugmentConfig, config.augment)
    step, history = _maybe_resume(resume, "fpn", model, optimizer, rng)
    log.write(event="start", model="fpn", step=step, code_version=_RUN_CODE_VERSION["at_start"], parameters=sum(p.numel() for p in model.parameters()), config=config.to_dict())

    def loss_at(step: int):
        image, target, valid = _fpn_batch(train_cities, rng, config, augmentation)
        with autocast(config, device):
            logits = model(image.to(device))
        return fpn_loss(logits.float(), target.to(device), valid.to(device), config), {}

    try:
        return optimize("fpn", model, model_config, config, out_dir, optimizer, rng, step, history, log, loss_at,
                        lambda step: validate_fpn(model, valid_batches, device, config), progress)
    finally:
        for city in (*train_cities, valid_city):
            city.close()


# -- AfANet -------------------------------------------------------------------------------------------


def adjacency_loss(logits: torch.Tensor, label: torch.Tensor, max_pos_weight: float) -> torch.Tensor:
    """BCE over the off-diagonal pairs, positives weighted by the negative/positive ratio."""
    m = logits.shape[0]
    off = ~torch.eye(m, dtype=torch.bool, device=logits.device)
    positives = label[off].sum()
    negatives = off.sum() - positives
    pos_weight = (negatives / positives.clamp(min=1)).clamp(1.0, max_pos_weight)
    return F.binary_cross_entropy_with_logits(logits[off], label[off], pos_weight=pos_weight)


def _afanet_sample(city: TrainingCity, window, rng: np.random.Generator, stage: str, config: TrainConfig, vertex_config: VertexConfig,
                   augmentation: AugmentConfig | None = None):
    """One AfANet example: the 6-channel tensor (image bands re-lit by ``augmentation`` when given;
    the FPN maps as predicted), vertices in window pixels and their adjacency label."""
    tensor = city.afanet_tensor(window)
    if augmentation is not None and augmentation.enabled:
        tensor[:4] = photometric(rng, tensor[:4], augmentation)
    if stage == "gt":
        vertices = city.gt_vertices(window)
        vertices = vertices + rng.normal(0, config.vertex_jitter_px, vertices.shape)
    else:
        graph = extract_vertices(tensor[4], vertex_config)
        local = np.concatenate([graph.vertices, added_crossings(graph, tensor[5], CrossingConfig(spacing_px=config.crossing_spacing_px))])
        vertices = local + np.array([window.col_off, window.row_off])
    if len(vertices) > config.max_vertices:
        vertices = vertices[np.sort(rng.choice(len(vertices), config.max_vertices, replace=False))]
    label = city.adjacency(vertices, window)
    local = vertices - np.array([window.col_off, window.row_off])
    return torch.from_numpy(tensor), torch.from_numpy(local.astype(np.float32)), torch.from_numpy(label.astype(np.float32))


@torch.no_grad()
def validate_afanet(model: AfANet, samples, device, max_pos_weight: float) -> dict[str, float]:
    model.eval()
    tp = fp = fn = 0
    losses = []
    for tensor, vertices, label in samples:
        if len(vertices) < 2:
            continue
        logits = model(tensor.to(device), vertices.to(device))
        losses.append(float(adjacency_loss(logits, label.to(device), max_pos_weight)))
        edges = set(edges_from_adjacency(model.adjacency(tensor.to(device), vertices.to(device))))
        truth = {(int(u), int(v)) for u, v in zip(*np.nonzero(np.triu(label.numpy(), 1)))}
        tp += len(edges & truth)
        fp += len(edges - truth)
        fn += len(truth - edges)
    model.train()
    precision, recall = tp / max(tp + fp, 1), tp / max(tp + fn, 1)
    return {"val_loss": float(np.mean(losses)) if losses else float("nan"), "val_edge_precision": precision,
            "val_edge_recall": recall, "val_edge_f1": 2 * precision * recall / max(precision + recall, 1e-9)}


def train_afanet(config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True) -> Path:
    seed_everything(config.seed)
    log = RunLog(out_dir / "train.log")
    if not config.fpn_weights:
        raise ValueError("AfANet training needs fpn_weights: the trained FPN whose maps it reads")
    fpn = load_fpn(config.fpn_weights, device)
    train_cities = training_cities(config)
    cities = {"valid": TrainingCity(config.valid_city.ensure(config.cache))}
    for city in (*train_cities, cities["valid"]):
        city.maps = predict_mosaic_maps(fpn, city.mosaic, city.labels.grid, device, progress)
    del fpn
    augmentation = _model_config(AugmentConfig, config.augment)
    model_config = _model_config(AfANetConfig, config.afanet)
    model = AfANet(model_config).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    vertex_config = VertexConfig()
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_windows = [cities["valid"].random_window(valid_rng, config.window) for _ in range(config.validation_samples)]
    valid_sets = {stage: [_afanet_sample(cities["valid"], w, valid_rng, stage, config, vertex_config) for w in valid_windows] for stage in ("gt", "pred")}
    rng = np.random.default_rng(config.seed)
    step, history = _maybe_resume(resume, "afanet", model, optimizer, rng)
    log.write(event="start", model="afanet", step=step, code_version=_RUN_CODE_VERSION["at_start"], parameters=sum(p.numel() for p in model.parameters()), config=config.to_dict())

    def loss_at(step: int):
        stage = "gt" if step < config.gt_steps else "pred"
        city = train_cities[int(rng.integers(len(train_cities)))] if len(train_cities) > 1 else train_cities[0]
        tensor, vertices, label = _afanet_sample(city, city.random_window(rng, config.window), rng, stage, config, vertex_config, augmentation)
        extras = {"stage": stage, "m": len(vertices)}
        if len(vertices) < 2:  # nothing to connect in this window
            return None, extras
        return adjacency_loss(model(tensor.to(device), vertices.to(device)), label.to(device), config.max_pos_weight), extras

    def validate(step: int) -> dict:
        metrics = {}
        for name, samples in valid_sets.items():
            metrics.update({f"{k}_{name}": v for k, v in validate_afanet(model, samples, device, config.max_pos_weight).items()})
        return metrics

    try:
        return optimize("afanet", model, model_config, config, out_dir, optimizer, rng, step, history, log, loss_at, validate, progress)
    finally:
        for city in (*train_cities, cities["valid"]):
            city.close()


# -- shared -------------------------------------------------------------------------------------------


def optimize(kind: str, model, model_config, config: TrainConfig, out_dir: Path, optimizer, rng: np.random.Generator, step: int,
             history: list, log: RunLog, loss_at, validate, progress: bool = True) -> Path:
    """The loop every trainer shares (the FPN, AfANet, the dense baselines): cosine learning
    rate, one optimizer step per ``loss_at(step) -> (loss, extras)`` (a ``None`` loss, e.g. an
    AfANet window with fewer than two vertices, counts the step without an update), a validation
    (``validate(step) -> dict``, logged with the extras) and a resumable checkpoint every
    ``validate_every`` steps, the final weights at the end."""
    model.train()
    bar = tqdm(total=config.steps, initial=step, desc=f"train {kind}", unit="step", disable=not progress)
    last = None
    while step < config.steps:
        lr = _cosine_lr(config, step)
        for group in optimizer.param_groups:
            group["lr"] = lr * group.get("lr_scale", 1.0)
        loss, extras = loss_at(step)
        if loss is not None:
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            last = loss.item()
        step += 1
        bar.update(1)
        if last is not None:
            bar.set_postfix(loss=f"{last:.4f}", **{k: f"{v:.3g}" if isinstance(v, float) else v for k, v in extras.items()})
        if step % config.validate_every == 0 or step == config.steps:
            metrics = {"step": step, "train_loss": last, "lr": lr, **extras, **validate(step)}
            _record(out_dir, kind, metrics, model, model_config, config, step, history, optimizer, rng, log)
    bar.close()
    return _finish(out_dir, kind, model, model_config, config, step, history, log)


def _model_config(cls, overrides: dict):
    """A model config from the training config's overrides; a misspelt key is an error."""
    return cls.from_dict(overrides)


def _cosine_lr(config: TrainConfig, step: int) -> float:
    """Short linear warm-up, then cosine decay to 5% of the base rate."""
    warm = max(1, config.steps // 50)
    if step < warm:
        return config.lr * (step + 1) / warm
    t = (step - warm) / max(1, config.steps - warm)
    return config.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(1.0, t))))


def _record(out_dir: Path, kind: str, metrics: dict, model, model_config, config, step, history, optimizer, rng, log: RunLog) -> None:
    """Log one validation and write the resumable ``<kind>-last.pt``."""
    history.append(metrics)
    log.write(event="validate", **metrics)
    _save(out_dir / f"{kind}-last.pt", kind, model, model_config, config, step, history, optimizer, rng)
    if config.snapshots:
        _save(out_dir / f"{kind}-step{step}.pt", kind, model, model_config, config, step, history, None)


def _finish(out_dir: Path, kind: str, model, model_config, config, step, history, log: RunLog) -> Path:
    """Write the final ``<kind>.pt`` (no optimizer state) and log its path."""
    final = out_dir / f"{kind}.pt"
    _save(final, kind, model, model_config, config, step, history, None)
    log.write(event="done", step=step, weights=str(final))
    return final


def _save(path: Path, kind: str, model, model_config, config: TrainConfig, step: int, history: list, optimizer, rng=None) -> None:
    content = {
        kind: model.state_dict(),
        f"{kind}_config": model_config.to_dict(),
        "train_config": config.to_dict(),
        "step": step,
        "validation": history,
        "code_version_at_start": _RUN_CODE_VERSION.get("at_start", code_version()),
    }
    if optimizer is not None:
        content["optimizer"] = optimizer.state_dict()
        content["torch_rng"] = torch.get_rng_state()
        content["numpy_rng"] = rng.bit_generator.state if rng is not None else None
        if torch.cuda.is_available():
            content["cuda_rng"] = torch.cuda.get_rng_state_all()
    save_checkpoint(path, kind, **content)


def _maybe_resume(resume: str | None, kind: str, model, optimizer, rng: np.random.Generator) -> tuple[int, list]:
    """Restore weights, optimizer and every random stream, so a resumed run continues exactly."""
    if not resume:
        return 0, []
    payload = load_checkpoint(resume, (kind,))
    model.load_state_dict(payload[kind])
    if "optimizer" in payload:
        optimizer.load_state_dict(payload["optimizer"])
    if "torch_rng" in payload:
        torch.set_rng_state(payload["torch_rng"])
    if payload.get("numpy_rng"):
        rng.bit_generator.state = payload["numpy_rng"]
    if payload.get("cuda_rng") and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(payload["cuda_rng"])
    return int(payload["step"]), list(payload.get("validation", []))
