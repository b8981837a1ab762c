"""AfANet training in two stages (ground-truth vertices, then the FPN's predicted ones): the
adjacency loss, the samples of whole windows, validation by edge F1, and the trainer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from csboundary.graph.crossings import CrossingConfig, added_crossings
from csboundary.graph.vertex_extraction import VertexConfig, extract_vertices
from csboundary.models.afanet import AfANet, AfANetConfig, edges_from_adjacency
from csboundary.models.augmentation import AugmentConfig, photometric
from csboundary.models.checkpoint import file_sha256, load_afanet, load_fpn
from csboundary.models.maps import predict_mosaic_maps
from csboundary.models.training.config import TrainConfig, extra_parts, model_config_with, training_cities
from csboundary.models.training.data import TrainingCity, city_probabilities
from csboundary.models.training.loop import RunLog, TrainingRun, optimize, run_code_version, seed_everything


def adjacency_loss(logits: torch.Tensor, label: torch.Tensor, max_pos_weight: float) -> torch.Tensor:
    """BCE over the off-diagonal pairs, positives weighted by the negative/positive ratio."""
    m = logits.shape[0]
    off = ~torch.eye(m, dtype=torch.bool, device=logits.device)
    positives = label[off].sum()
    negatives = off.sum() - positives
    pos_weight = (negatives / positives.clamp(min=1)).clamp(1.0, max_pos_weight)
    return F.binary_cross_entropy_with_logits(logits[off], label[off], pos_weight=pos_weight)


def _afanet_sample(
    city: TrainingCity,
    window,
    rng: np.random.Generator,
    stage: str,
    config: TrainConfig,
    vertex_config: VertexConfig,
    augmentation: AugmentConfig | None = None,
):
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
        local = np.concatenate(
            [graph.vertices, added_crossings(graph, tensor[5], CrossingConfig(spacing_px=config.crossing_spacing_px))]
        )
        vertices = local + np.array([window.col_off, window.row_off])
    vertices = vertices[city.labelled(vertices)]  # a vertex outside a reviewed city's complete area has no known edges
    if len(vertices) > config.max_vertices:
        vertices = vertices[np.sort(rng.choice(len(vertices), config.max_vertices, replace=False))]
    label = city.adjacency(vertices, window)
    local = vertices - np.array([window.col_off, window.row_off])
    return (
        torch.from_numpy(tensor),
        torch.from_numpy(local.astype(np.float32)),
        torch.from_numpy(label.astype(np.float32)),
    )


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
    return {
        "val_loss": float(np.mean(losses)) if losses else float("nan"),
        "val_edge_precision": precision,
        "val_edge_recall": recall,
        "val_edge_f1": 2 * precision * recall / max(precision + recall, 1e-9),
    }


def starting_afanet(config: TrainConfig, device: torch.device) -> tuple[AfANet, AfANetConfig]:
    """The AfANet a run starts from and its config: ``init_afanet``'s (a checkpoint or a bundle,
    its recorded architecture) when given, else a new one of ``config.afanet``."""
    if not config.init_afanet:
        model_config = model_config_with(AfANetConfig, config.afanet)
        return AfANet(model_config).to(device), model_config
    model = load_afanet(config.init_afanet, device)
    return model, model.config


def train_afanet(
    config: TrainConfig, out_dir: Path, device: torch.device, resume: str | None = None, progress: bool = True
) -> Path:
    seed_everything(config.seed)
    log = RunLog(out_dir / "train.log")
    if not config.fpn_weights:
        raise ValueError("AfANet training needs fpn_weights: the trained FPN whose maps it reads")
    fpn = load_fpn(config.fpn_weights, device)
    train_cities = training_cities(config, progress)
    cities = {"valid": TrainingCity(config.valid_city.ensure(config.cache, progress))}
    for city in (*train_cities, cities["valid"]):
        city.maps = predict_mosaic_maps(fpn, city.mosaic, city.labels.grid, device, progress)
    del fpn
    augmentation = model_config_with(AugmentConfig, config.augment)
    model, model_config = starting_afanet(config, device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    vertex_config = VertexConfig(threshold=config.vertex_threshold)
    valid_rng = np.random.default_rng(config.seed + 1)
    valid_windows = [cities["valid"].random_window(valid_rng, config.window) for _ in range(config.validation_samples)]
    valid_sets = {
        stage: [_afanet_sample(cities["valid"], w, valid_rng, stage, config, vertex_config) for w in valid_windows]
        for stage in ("gt", "pred")
    }
    rng = np.random.default_rng(config.seed)
    run = TrainingRun("afanet", model, model_config, config, out_dir, optimizer, rng, log).resumed(resume)
    init = {"init_afanet_sha256": file_sha256(config.init_afanet)} if config.init_afanet else {}
    log.write(
        event="start",
        model="afanet",
        step=run.step,
        code_version=run_code_version(),
        parameters=sum(p.numel() for p in model.parameters()),
        config=config.to_dict(),
        **init,
    )

    probabilities = city_probabilities(
        train_cities, extra_parts(train_cities, config), config.extra_share, by_area=False
    )

    def loss_at(step: int):
        stage = "gt" if step < config.gt_steps else "pred"
        if len(train_cities) == 1:
            city = train_cities[0]
        elif config.extra_share > 0:
            city = train_cities[int(rng.choice(len(train_cities), p=probabilities))]
        else:  # as recorded runs drew their cities
            city = train_cities[int(rng.integers(len(train_cities)))]
        tensor, vertices, label = _afanet_sample(
            city, city.random_window(rng, config.window), rng, stage, config, vertex_config, augmentation
        )
        extras = {"stage": stage, "m": len(vertices)}
        if len(vertices) < 2:  # nothing to connect in this window
            return None, extras
        return adjacency_loss(
            model(tensor.to(device), vertices.to(device)), label.to(device), config.max_pos_weight
        ), extras

    def validate(step: int) -> dict:
        metrics = {}
        for name, samples in valid_sets.items():
            metrics.update(
                {f"{k}_{name}": v for k, v in validate_afanet(model, samples, device, config.max_pos_weight).items()}
            )
        return metrics

    try:
        return optimize(run, loss_at, validate, progress)
    finally:
        for city in (*train_cities, cities["valid"]):
            city.close()
