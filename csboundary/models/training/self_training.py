"""The mean-teacher self-training of the FPN on unlabelled imagery: the method behind the
``adapt`` workflow (:mod:`csboundary.pipeline.training.adapt`).

The synthetic-to-real gap in dense prediction has a standard cure (DACS, DAFormer): a teacher
that is the exponential moving average (EMA) of the student labels the target images; the
student learns from the teacher's confident pixels under strong augmentation, beside labelled
source images, and source regions pasted into target images carry their true labels across.
Here:

* the **teacher** is the EMA of the student's weights; it sees each target window as read
  (flipped or turned only) and its keypoint, boundary and road-surface probabilities become the
  pseudo-labels, weighted per pixel by the teacher's confidence ``|2q - 1|`` (not the keypoint
  heat). The networks learnt with positives weighted up (``pos_weight_*``), so a probability p
  they give is the posterior q = p / (w - (w - 1) p) inflated; the targets are q, so that the
  student's optimum under the same weighted loss is the teacher's p. Targets p instead drift: each
  round of teaching inflates the maps again (measured: boundary precision on a synthetic city fell
  from 0.35 to 0.19 in 400 steps);
* the **student** sees the same window re-lit and degraded (strong photometric augmentation);
* **synthetic labelled windows** of the bundle's style mix make up the rest of every batch, so
  what the model learnt there is kept;
* **cross-domain mixing**: the roadway of a synthetic window (its road surface, widened to take in
  the curb) is pasted into the target window, with its true labels;
* the **road surface as an anchor**: a boundary is where the roadway ends, so every pixel
  farther than ``anchor_px`` from an edge of the teacher's own roadway is taught as background
  of the boundary map, with full weight.

Each part is a switch of :class:`AdaptConfig`; ``docs/experiments.md`` records what each does.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from csboundary.config import Config
from csboundary.models.augmentation import AugmentConfig, flip_rotate90, photometric
from csboundary.models.checkpoint import file_sha256, save_checkpoint
from csboundary.models.style_mixing import add_style_mixing
from csboundary.models.training.config import TrainConfig, model_config_with, training_cities
from csboundary.models.training.data import TrainingCity
from csboundary.models.training.fpn import fpn_batch, fpn_loss, fpn_parameter_groups, starting_fpn, validate_fpn
from csboundary.models.training.loop import RunLog, TrainingRun, autocast, optimize, run_code_version, seed_everything
from csboundary.models.training.unlabelled import UnlabelledImagery


@dataclass(frozen=True)
class AdaptConfig(Config):
    """The self-training method's settings (module doc); the budget and the source recipe are
    the run's :class:`TrainConfig`. Stored in the run's ``options``."""

    config_name = "adapt"

    source_batch: int = 2  # synthetic labelled windows per step
    target_batch: int = 2  # windows of the user's imagery per step
    ema_decay: float = 0.99  # teacher = decay x teacher + (1 - decay) x student, every step
    target_weight: float = (
        0.3  # the pseudo-label loss's weight beside the source loss: 0.3 kept APLS on both real sets (docs/adapt.md)
    )
    confidence_weighting: bool = True  # weight each pseudo-label by the teacher's confidence |2q - 1|; else 1
    hard_labels: bool = (
        False  # boundary and surface targets 0/1 (q > 0.5) rather than q: sharpens, and thins weak boundaries
    )
    strong_augment: bool = True  # the student sees the target re-lit and degraded; else as the teacher does
    mix: bool = True  # paste synthetic roadway (with its labels) into the target windows
    mix_widen_px: int = 8  # the pasted roadway is widened by this to carry its curb and boundary along
    surface_anchor: bool = True  # pixels farther than anchor_px from the teacher's roadway edge are boundary background
    anchor_px: int = 6
    export: str = "teacher"  # teacher | student: the network written as the adapted FPN


class MeanTeacher(torch.nn.Module):
    """A student network and its EMA teacher, saved and restored together (an exact resume)."""

    def __init__(self, student: torch.nn.Module):
        super().__init__()
        self.teacher = copy.deepcopy(student)
        self.teacher.requires_grad_(False)
        self.student = student

    def train(self, mode: bool = True) -> "MeanTeacher":
        self.training = mode
        self.student.train(mode)
        self.teacher.eval()  # the teacher's batch statistics are the EMA's, never a batch's
        return self

    @torch.no_grad()
    def update_teacher(self, decay: float) -> None:
        """Move every teacher weight and batch-norm statistic ``1 - decay`` of the way to the student's."""
        for t, s in zip(self.teacher.state_dict().values(), self.student.state_dict().values()):
            if t.dtype.is_floating_point:
                t.mul_(decay).add_(s, alpha=1 - decay)
            else:
                t.copy_(s)

    @torch.no_grad()
    def pseudo_maps(self, image: torch.Tensor) -> torch.Tensor:
        """(B, C, H, W) teacher probabilities of ``image``."""
        self.teacher.eval()
        return torch.sigmoid(self.teacher(image))


def roadway_edge_near(surface: torch.Tensor, px: int) -> torch.Tensor:
    """(B, H, W) bool: pixels within ``px`` of an edge of the roadway ``surface > 0.5`` (B, H, W)."""
    road = (surface > 0.5).float()[:, None]
    grown = F.max_pool2d(road, 3, stride=1, padding=1)
    shrunk = -F.max_pool2d(-road, 3, stride=1, padding=1)
    edge = (grown - shrunk) > 0
    return F.max_pool2d(edge.float(), 2 * px + 1, stride=1, padding=px)[:, 0] > 0


def posterior(maps: torch.Tensor, pos_weights: tuple[float, ...]) -> torch.Tensor:
    """The probabilities ``maps`` (B, C, H, W) of a network trained with channel c's positives
    weighted ``pos_weights[c]`` (1 for channels beyond the tuple), turned back into posteriors:
    q = p / (w - (w - 1) p)."""
    w = torch.ones(maps.shape[1], dtype=maps.dtype, device=maps.device)
    w[: len(pos_weights)] = torch.tensor(pos_weights, dtype=maps.dtype, device=maps.device)
    w = w.view(1, -1, 1, 1)
    return maps / (w - (w - 1) * maps)


def pseudo_labels(
    maps: torch.Tensor, valid: torch.Tensor, settings: AdaptConfig, pos_weights: tuple[float, ...] = (1.0, 1.0)
) -> tuple[torch.Tensor, torch.Tensor]:
    """Targets and per-pixel weights (B, C, H, W) from teacher probabilities ``maps`` (module
    doc): posteriors (hard for boundary and surface with ``hard_labels``), weighted by their
    confidence except the keypoint heat; boundary pixels away from the roadway's edge taught as
    background (``surface_anchor``); no weight off the imagery (``valid`` (B, H, W) false)."""
    q = posterior(maps, pos_weights)
    target = q.clone()
    if settings.hard_labels:
        target[:, 1:] = (q[:, 1:] > 0.5).to(maps.dtype)
    weight = (2 * q - 1).abs() if settings.confidence_weighting else torch.ones_like(maps)
    weight[:, 0] = 1.0
    if settings.surface_anchor and maps.shape[1] > 2:
        away = ~roadway_edge_near(maps[:, 2], settings.anchor_px)
        target[:, 1][away] = 0.0
        weight[:, 1][away] = 1.0
    return target, weight * valid[:, None].to(maps.dtype)


def pseudo_label_loss(
    logits: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, config: TrainConfig
) -> torch.Tensor:
    """Weighted BCE of keypoint and boundary (with the recipe's positive weights) plus
    ``surface_weight`` x the surface BCE, each normalised by its weights' sum."""
    pos = torch.tensor([config.pos_weight_keypoint, config.pos_weight_segmentation], device=logits.device).view(
        1, 2, 1, 1
    )
    maps = F.binary_cross_entropy_with_logits(logits[:, :2], target[:, :2], pos_weight=pos, reduction="none")
    total = (maps * weight[:, :2]).sum() / weight[:, :2].sum().clamp(min=1)
    if logits.shape[1] > 2 and target.shape[1] > 2:
        road = F.binary_cross_entropy_with_logits(logits[:, 2], target[:, 2], reduction="none")
        total = total + config.surface_weight * (road * weight[:, 2]).sum() / weight[:, 2].sum().clamp(min=1)
    return total


def paste_roadway(image: np.ndarray, target: np.ndarray, weight: np.ndarray, source: tuple, widen_px: int) -> float:
    """Paste the roadway of a synthetic ``source`` sample (image, targets with a surface channel,
    valid) into a target window, in place: image, targets and weights (C, H, W) take the
    source's inside the widened roadway; returns the pasted share of the window."""
    import cv2

    src_image, src_target, src_valid = source
    road = (src_target[2] > 0.5).astype(np.uint8)
    if widen_px > 0 and road.any():
        road = cv2.dilate(road, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * widen_px + 1, 2 * widen_px + 1)))
    paste = road.astype(bool) & src_valid
    image[:, paste] = src_image[:, paste]
    target[:, paste] = src_target[:, paste]
    weight[:, paste] = 1.0
    return float(paste.mean())


def _target_batch(
    imagery: UnlabelledImagery, rng: np.random.Generator, count: int, crop: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """``count`` target windows as the teacher sees them: read, then flipped or turned."""
    images, valids = [], []
    for _ in range(count):
        image, valid = imagery.sample(rng, crop)
        image, valid = flip_rotate90(rng, image, valid)
        images.append(image)
        valids.append(valid)
    return torch.from_numpy(np.stack(images)), torch.from_numpy(np.stack(valids))


def train_adapt(
    config: TrainConfig,
    imagery: UnlabelledImagery,
    out_dir: Path,
    device: torch.device,
    resume: str | None = None,
    progress: bool = True,
) -> Path:
    """Self-train the FPN ``config.init_fpn`` on ``imagery`` (settings in ``config.options["method"]``);
    writes the run (``adapt-last.pt`` to resume, ``train.log``) and returns the adapted FPN
    checkpoint ``fpn.pt`` (the teacher, or the student, as ``export`` says)."""
    settings = AdaptConfig.from_dict(config.options.get("method", {}))
    seed_everything(config.seed)
    log = RunLog(out_dir / "train.log")
    source_cities = training_cities(config, progress)
    valid_city = TrainingCity(config.valid_city.ensure(config.cache, progress))
    student, model_config = starting_fpn(config, device)
    if not model_config.surface and (settings.mix or settings.surface_anchor):
        raise ValueError("mixing and the surface anchor need an FPN with a road-surface head")
    model = MeanTeacher(student)
    add_style_mixing(student, config.style_mix, config.style_mix_alpha)
    optimizer = torch.optim.Adam(fpn_parameter_groups(student, config), lr=config.lr, weight_decay=config.weight_decay)
    rng = np.random.default_rng(config.seed)
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_batches = [fpn_batch([valid_city], valid_rng, config, None, True) for _ in range(config.validation_samples)]
    augmentation = model_config_with(AugmentConfig, config.augment)
    run = TrainingRun("adapt", model, model_config, config, out_dir, optimizer, rng, log).resumed(resume)
    log.write(
        event="start",
        model="adapt",
        step=run.step,
        code_version=run_code_version(),
        config=config.to_dict(),
        init_fpn_sha256=file_sha256(config.init_fpn),
        target_pixels=imagery.pixels,
    )
    source_config = copy.copy(config)
    source_config.batch = settings.source_batch

    def loss_at(step: int):
        model.update_teacher(settings.ema_decay if step > 0 else 0.0)
        loss = torch.zeros((), device=device)
        if settings.source_batch > 0:
            image, target, valid = fpn_batch(source_cities, rng, source_config, augmentation, True)
            image = image.to(device)
            with autocast(config, device):
                logits = student(image)
            loss = loss + fpn_loss(logits.float(), target.to(device), valid.to(device), config, image)
        image, valid = _target_batch(imagery, rng, settings.target_batch, config.crop)
        maps = model.pseudo_maps(image.to(device))
        target, weight = pseudo_labels(
            maps, valid.to(device), settings, (config.pos_weight_keypoint, config.pos_weight_segmentation)
        )
        image, target, weight = image.numpy().copy(), target.cpu().numpy(), weight.cpu().numpy()
        pasted = []
        for k in range(len(image)):
            if settings.mix:
                source = source_cities[int(rng.integers(len(source_cities)))].augmented_fpn_sample(
                    rng, config.crop, augmentation, True
                )
                pasted.append(paste_roadway(image[k], target[k], weight[k], source, settings.mix_widen_px))
            if settings.strong_augment:
                image[k] = photometric(rng, image[k], augmentation)
        with autocast(config, device):
            logits = student(torch.from_numpy(image).to(device))
        loss = loss + settings.target_weight * pseudo_label_loss(
            logits.float(), torch.from_numpy(target).to(device), torch.from_numpy(weight).to(device), config
        )
        extras = {
            "pseudo_boundary": float((target[:, 1] > 0.5).mean()),
            "confident": float((weight[:, 1] > 0.8).mean()),
        }
        if pasted:
            extras["pasted"] = float(np.mean(pasted))
        return loss, extras

    try:
        optimize(
            run,
            loss_at,
            lambda step: validate_fpn(getattr(model, settings.export), valid_batches, device, config),
            progress,
        )
    finally:
        for city in (*source_cities, valid_city):
            city.close()
    model.teacher.eval()  # validate_fpn leaves the network it scored in train mode
    final = out_dir / "fpn.pt"
    save_checkpoint(
        final,
        "fpn",
        fpn=getattr(model, settings.export).state_dict(),
        fpn_config=model_config.to_dict(),
        train_config=config.to_dict(),
        step=config.steps,
        validation=run.history,
        code_version_at_start=run_code_version(),
    )
    return final
