"""What a training run depends on (:class:`TrainConfig`) and what is read from it: the cities it
trains on, their pixel size, the model configs built from its overrides."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from csboundary.config import Config
from csboundary.data import city_layout
from csboundary.errors import InputError
from csboundary.models.training.data import CitySpec, TrainingCity, WorldsConfig


@dataclass
class TrainConfig(Config):
    """Everything a run depends on; stored in every checkpoint and in the log."""

    config_name = "training"
    config_nested = {"train_city": CitySpec, "valid_city": CitySpec}

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
    # city directories (imported, from masks, a user's own) trained on beside train_city
    extra_train_cities: list = field(default_factory=list)
    # share of samples drawn from extra_train_cities (fine-tuning on a user's city); 0 = every city by its area (FPN)
    # or alike (AfANet)
    extra_share: float = 0.0
    augment: dict = field(
        default_factory=lambda: {"enabled": False}
    )  # AugmentConfig overrides; {} = every augmentation at its defaults
    snapshots: bool = (
        False  # also keep <kind>-step<N>.pt (weights only) at every validation, for selecting a model on other data
    )
    encoder_lr_scale: float = (
        1.0  # pretrained FPN encoder: its learning rate relative to lr (a small one keeps ImageNet features)
    )
    freeze_encoder_bn: bool = (
        False  # pretrained FPN encoder: keep its batch-norm statistics (ImageNet's, not the synthetic cities')
    )
    # pretrained FPN encoder: probability per batch of mixing early feature statistics between samples (MixStyle); 0 = off
    style_mix: float = 0.0
    style_mix_alpha: float = 0.1  # Beta(alpha, alpha) of the mixing weight
    autocast_bf16: bool = (
        False  # bfloat16 autocast of forward passes (CPUs with AVX-512 BF16, GPUs); float32 when false
    )
    # fpn
    fpn: dict = field(default_factory=dict)  # FPNConfig overrides
    init_fpn: str = (
        ""  # start from this trained FPN (fpn checkpoint or bundle; its architecture, not ``fpn``): fine-tuning
    )
    surface: bool = False  # add (or keep) the road-surface head; with init_fpn, a network without one gains a new head
    # train the surface head alone: every other weight frozen, so the keypoint and boundary maps stay as they were
    surface_only: bool = False
    surface_weight: float = 1.0  # the surface loss's weight beside the keypoint and boundary losses
    crop: int = 256
    batch: int = 4
    pos_weight_keypoint: float = 20.0
    pos_weight_segmentation: float = 10.0
    # extra loss weight on keypoint/boundary negatives where the image has an edge (roofs, cars, lots); 0 = off
    hard_negative_weight: float = 0.0
    hard_negative_margin_px: int = 6  # pixels this close to a true boundary are never hard negatives
    # pretrained FPN encoder: weight of the distance of its bottleneck features to the frozen ImageNet encoder's (DAFormer); 0 = off
    feature_distance_weight: float = 0.0
    # afanet
    afanet: dict = field(default_factory=dict)  # AfANetConfig overrides
    fpn_weights: str = ""  # the trained FPN whose maps and vertices AfANet learns from
    # start from this trained AfANet (afanet checkpoint or bundle; its architecture, not ``afanet``): fine-tuning
    init_afanet: str = ""
    window: int = 1100  # AfANet trains on whole expanded-patch-sized windows, as it infers
    gt_steps: int = 600  # stage 1 (ground-truth vertices); the rest of ``steps`` is stage 2
    vertex_jitter_px: float = 1.0  # noise on ground-truth vertices in stage 1
    vertex_threshold: float = (
        0.5  # stage 2: keypoint probability of the FPN's extracted vertices (as the bundle will infer)
    )
    crossing_spacing_px: int = (
        0  # AfANet stage 2: also the FPN segmentation's grid-crossing vertices (csboundary.graph.crossings)
    )
    max_vertices: int = 160
    max_pos_weight: float = 30.0
    # baselines (csboundary.models.baselines): method-specific settings, documented per method
    options: dict = field(default_factory=dict)

    @classmethod
    def from_file(cls, path: str | Path) -> "TrainConfig":
        """A config file, which must name its training data: ``{}`` would otherwise silently
        train on the default synthetic city."""
        data = json.loads(Path(path).read_text())
        if not isinstance(data, dict):
            raise ValueError("not a JSON object of settings")
        if not any(key in data for key in TRAINING_DATA):
            raise ValueError(f"names no training data: give one of {', '.join(TRAINING_DATA)} (see configs/)")
        return cls.from_dict(data)


TRAINING_DATA = ("train_city", "worlds", "extra_train_cities")  # the keys that say what a config trains on


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
        if city_layout.is_city_dir(path):
            metres = city_layout.pixel_metres(
                city_layout.read_meta(path)
            )  # not city.json's gsd: that is in CRS units (feet in NYC)
            if metres is not None:
                sizes.add(round(metres, 6))
    return sizes.pop() if len(sizes) == 1 else None


def training_cities(config: TrainConfig, progress: bool = True) -> list[TrainingCity]:
    """The synthetic ``train_city`` and ``worlds`` cities (built on first use) and every
    ``extra_train_cities`` directory."""
    specs = [config.train_city] if config.train_city is not None else []
    if config.worlds:
        specs += WorldsConfig.from_dict(config.worlds).specs()
    if not specs and not config.extra_train_cities:
        raise ValueError("the training config names no training city (train_city, worlds or extra_train_cities)")
    paths = [spec.ensure(config.cache, progress=progress and len(specs) == 1) for spec in specs] + list(
        config.extra_train_cities
    )
    for path in config.extra_train_cities:
        if not city_layout.is_city_dir(path):
            raise InputError(
                path, "not a city directory (tiles/, ground_truth.gpkg and city.json; see csboundary import-masks)"
            )
    return [city for p in paths for city in TrainingCity.parts(p)]


def extra_parts(cities: list[TrainingCity], config: TrainConfig) -> int:
    """How many of ``cities`` (the last ones) are parts of ``extra_train_cities``."""
    extra = {Path(p) for p in config.extra_train_cities}
    return sum(Path(c.path) in extra for c in cities)


def model_config_with(cls, overrides: dict):
    """A model config (``cls``: FPNConfig, AfANetConfig, AugmentConfig, ...) from the training
    config's overrides; a misspelt key is an error."""
    return cls.from_dict(overrides)
