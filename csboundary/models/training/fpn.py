"""FPN training: the weighted BCE on keypoint heat and segmentation, batches of random crops,
validation by segmentation F1, the optimizer groups of a pretrained encoder, and the trainer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from csboundary.models.augmentation import AugmentConfig
from csboundary.models.checkpoint import file_sha256, load_checkpoint, load_fpn
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.style_mixing import add_style_mixing
from csboundary.models.training.config import TrainConfig, extra_parts, model_config_with, training_cities
from csboundary.models.training.data import TrainingCity, city_probabilities
from csboundary.models.training.feature_distance import FeatureAnchor
from csboundary.models.training.loop import RunLog, TrainingRun, autocast, optimize, run_code_version, seed_everything


def fpn_parameter_groups(model, config: TrainConfig) -> list[dict]:
    """Optimizer groups: a pretrained encoder at ``encoder_lr_scale`` of the rate, the rest at 1
    (``lr_scale`` is read by the schedule); sets the encoder's batch-norm freeze."""
    encoder = getattr(model, "encoder", None)
    if encoder is None:
        return [{"params": list(model.parameters()), "lr_scale": 1.0}]
    model.freeze_encoder_bn = config.freeze_encoder_bn
    inside = {id(p) for p in encoder.parameters()}
    return [
        {"params": list(encoder.parameters()), "lr_scale": config.encoder_lr_scale},
        {"params": [p for p in model.parameters() if id(p) not in inside], "lr_scale": 1.0},
    ]


def image_edges(image: torch.Tensor) -> torch.Tensor:
    """(B, 1, H, W) in [0, 1]: the Sobel gradient magnitude of each sample's mean band, divided
    by its 95th percentile and clipped: 1 on every strong outline of the scene."""
    gray = image[:, :3].mean(dim=1, keepdim=True)
    kx = torch.tensor(
        [[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]], device=image.device, dtype=gray.dtype
    ).view(1, 1, 3, 3)
    padded = F.pad(gray, (1, 1, 1, 1), mode="replicate")
    magnitude = torch.sqrt(F.conv2d(padded, kx) ** 2 + F.conv2d(padded, kx.transpose(2, 3)) ** 2)
    scale = torch.quantile(magnitude.flatten(1), 0.95, dim=1).clamp(min=1e-6).view(-1, 1, 1, 1)
    return (magnitude / scale).clamp(max=1.0)


def hard_negative_weights(image: torch.Tensor, target: torch.Tensor, config: TrainConfig) -> torch.Tensor:
    """(B, 1, H, W) loss weights of the keypoint and boundary maps: 1, plus
    ``hard_negative_weight`` x the image's edge strength on pixels farther than
    ``hard_negative_margin_px`` from a true boundary. Why: on real photographs the boundary map
    fires on every outline (roofs, parapets, cars, lots); with plain BCE those pixels are a small
    share of the negatives and cost little."""
    m = config.hard_negative_margin_px
    near = F.max_pool2d((target[:, 1:2] > 0.5).to(image.dtype), 2 * m + 1, stride=1, padding=m)
    return 1.0 + config.hard_negative_weight * image_edges(image) * (1.0 - near)


def fpn_loss(
    logits: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    config: TrainConfig,
    image: torch.Tensor | None = None,
) -> torch.Tensor:
    """Weighted BCE of the keypoint and boundary maps on valid pixels (negatives on the image's
    outlines weighted up when ``hard_negative_weight`` and ``image`` are given); with a surface
    channel (logits and target (B, 3, ...)), plus ``surface_weight`` x the surface BCE on valid
    pixels whose surface is known (target >= 0); with ``surface_only``, the surface term alone."""
    weights = torch.tensor([config.pos_weight_keypoint, config.pos_weight_segmentation], device=logits.device).view(
        1, 2, 1, 1
    )
    mask = valid[:, None].to(logits.dtype)
    total = logits.new_zeros(())
    if not config.surface_only:
        loss = F.binary_cross_entropy_with_logits(logits[:, :2], target[:, :2], pos_weight=weights, reduction="none")
        if config.hard_negative_weight > 0 and image is not None:
            loss = loss * hard_negative_weights(image.to(logits.dtype), target[:, :2], config)
        total = (loss * mask).sum() / (mask.sum() * 2).clamp(min=1)
    if logits.shape[1] > 2 and target.shape[1] > 2:
        known = mask[:, 0] * (target[:, 2] >= 0).to(logits.dtype)
        road = F.binary_cross_entropy_with_logits(logits[:, 2], target[:, 2].clamp(min=0), reduction="none")
        total = total + config.surface_weight * (road * known).sum() / known.sum().clamp(min=1)
    return total


def starting_fpn(config: TrainConfig, device: torch.device):
    """The network a run starts from and its config: ``init_fpn`` (its recorded architecture),
    given a new surface head when ``config.surface`` asks for one it lacks; else a new FPN of
    ``config.fpn``. With ``surface_only``, every weight but the surface head's is frozen (the
    training step also keeps the frozen batch norms in eval mode)."""
    import dataclasses

    if config.init_fpn:
        trained = load_fpn(config.init_fpn, device).to(memory_format=torch.contiguous_format)
        recorded = load_checkpoint(config.init_fpn, ("fpn", "bundle"))["fpn_config"]
        model_config = dataclasses.replace(
            trained.config, pretrained=bool(recorded.get("pretrained", True))
        )  # how it began, as recorded
        if config.surface and not model_config.surface:
            model_config = dataclasses.replace(model_config, surface=True)
            model = FPN(dataclasses.replace(model_config, pretrained=False)).to(
                device
            )  # its weights come from init_fpn
            missing, unexpected = model.load_state_dict(trained.state_dict(), strict=False)
            if unexpected or any(not k.startswith("surface_head.") for k in missing):
                raise ValueError(f"{config.init_fpn}: weights do not fit the FPN with a surface head")
        else:
            model = trained
    else:
        model_config = model_config_with(
            FPNConfig, {**config.fpn, "surface": config.surface or config.fpn.get("surface", False)}
        )
        model = FPN(model_config).to(device)
    if config.surface_only:
        if not model_config.surface:
            raise ValueError("surface_only needs a surface head: set surface true")
        for name, parameter in model.named_parameters():
            parameter.requires_grad_(name.startswith("surface_head."))
    return model, model_config


def fpn_batch(
    cities: list[TrainingCity],
    rng: np.random.Generator,
    config: TrainConfig,
    augmentation: AugmentConfig | None,
    surface: bool = False,
):
    """``config.batch`` samples, each from a city drawn in proportion to its area; augmented
    (:mod:`csboundary.models.augmentation`) when ``augmentation`` is given (training), as they are
    otherwise (validation)."""
    probabilities = city_probabilities(cities, extra_parts(cities, config), config.extra_share, by_area=True)
    images, targets, valids = [], [], []
    for _ in range(config.batch):
        city = cities[int(rng.choice(len(cities), p=probabilities))] if len(cities) > 1 else cities[0]
        if augmentation is not None:
            image, target, valid = city.augmented_fpn_sample(rng, config.crop, augmentation, surface)
        else:
            image, target, valid = city.fpn_sample(city.random_window(rng, config.crop), surface)
        images.append(image)
        targets.append(target)
        valids.append(valid)
    return torch.from_numpy(np.stack(images)), torch.from_numpy(np.stack(targets)), torch.from_numpy(np.stack(valids))


@torch.no_grad()
def validate_fpn(model: FPN, batches, device, config: TrainConfig) -> dict[str, float]:
    model.eval()
    losses, tp, fp, fn = [], 0, 0, 0
    road = np.zeros(3)  # surface: intersection, union, pixels known
    for image, target, valid in batches:
        logits = model(image.to(device))
        losses.append(float(fpn_loss(logits, target.to(device), valid.to(device), config)))
        if logits.shape[1] > 2 and target.shape[1] > 2:
            known = valid & (target[:, 2] >= 0)
            pred, truth = (logits[:, 2] > 0).cpu() & known, (target[:, 2] > 0.5) & known
            road += [int((pred & truth).sum()), int((pred | truth).sum()), int(known.sum())]
        pred = (torch.sigmoid(logits[:, 1]) > 0.5).cpu() & valid
        truth = (target[:, 1] > 0.5) & valid
        tp += int((pred & truth).sum())
        fp += int((pred & ~truth).sum())
        fn += int((~pred & truth).sum())
    model.train()
    precision, recall = tp / max(tp + fp, 1), tp / max(tp + fn, 1)
    scores = {
        "val_loss": float(np.mean(losses)),
        "val_seg_precision": precision,
        "val_seg_recall": recall,
        "val_seg_f1": 2 * precision * recall / max(precision + recall, 1e-9),
    }
    if road[2]:
        scores["val_surface_iou"] = float(road[0] / max(road[1], 1))
    return scores


def train_fpn(
    config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True
) -> Path:
    seed_everything(config.seed)
    log = RunLog(out_dir / "train.log")
    train_cities = training_cities(config, progress)
    valid_city = TrainingCity(config.valid_city.ensure(config.cache, progress))
    model, model_config = starting_fpn(config, device)
    add_style_mixing(model, config.style_mix, config.style_mix_alpha)
    anchor = FeatureAnchor(model) if config.feature_distance_weight > 0 else None
    groups = (
        [{"params": [p for p in model.parameters() if p.requires_grad], "lr_scale": 1.0}]
        if config.surface_only
        else fpn_parameter_groups(model, config)
    )
    optimizer = torch.optim.Adam(groups, lr=config.lr, weight_decay=config.weight_decay)
    rng = np.random.default_rng(config.seed)
    valid_rng = np.random.default_rng(config.seed + 1)
    with_surface = bool(model_config.surface)
    if with_surface and all(city.surface is None for city in train_cities):
        raise ValueError(
            "the surface head needs cities with a road_surface layer (synthetic cities built by this version)"
        )
    valid_batches = [
        fpn_batch([valid_city], valid_rng, config, None, with_surface) for _ in range(config.validation_samples)
    ]
    augmentation = model_config_with(AugmentConfig, config.augment)
    run = TrainingRun("fpn", model, model_config, config, out_dir, optimizer, rng, log).resumed(resume)
    init = {"init_fpn_sha256": file_sha256(config.init_fpn)} if config.init_fpn else {}
    log.write(
        event="start",
        model="fpn",
        step=run.step,
        code_version=run_code_version(),
        parameters=sum(p.numel() for p in model.parameters()),
        config=config.to_dict(),
        **init,
    )

    def loss_at(step: int):
        if config.surface_only:  # frozen layers keep their batch statistics: the maps stay the trained FPN's
            for name, module in model.named_modules():
                if isinstance(module, torch.nn.BatchNorm2d) and not name.startswith("surface_head."):
                    module.eval()
        image, target, valid = fpn_batch(train_cities, rng, config, augmentation, with_surface)
        with autocast(config, device):
            logits = model(image.to(device))
        loss = fpn_loss(logits.float(), target.to(device), valid.to(device), config, image.to(device))
        if anchor is None:
            return loss, {}
        distance = anchor.take()
        return loss + config.feature_distance_weight * distance, {"feature_distance": float(distance)}

    try:
        return optimize(run, loss_at, lambda step: validate_fpn(model, valid_batches, device, config), progress)
    finally:
        if anchor is not None:
            anchor.close()
        for city in (*train_cities, valid_city):
            city.close()
