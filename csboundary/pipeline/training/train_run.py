"""A training run from a config file, whatever the model (``csboundary train``): the config is
read and checked against the model named, overridden where asked, recorded beside the weights,
and handed to the model's trainer (the FPN's, AfANet's or a baseline's)."""

from __future__ import annotations

import json
from pathlib import Path

from csboundary.data.atomic import atomic_path
from csboundary.errors import InputError
from csboundary.models.baselines import METHODS, baseline_module
from csboundary.models.device import resolve_device
from csboundary.models.training.afanet import train_afanet
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.fpn import train_fpn

MODELS = ("fpn", "afanet", *METHODS)


def train_from_file(
    model: str,
    config: str | Path,
    out: str | Path,
    *,
    resume: str | Path | None = None,
    steps: int | None = None,
    fpn_weights: str | Path | None = None,
    device: str = "auto",
    progress: bool = True,
) -> tuple[Path, TrainConfig]:
    """Train ``model`` (one of :data:`MODELS`) as the JSON ``config`` says into the run folder
    ``out`` (config.json, train.log, checkpoints), resuming from the checkpoint ``resume``;
    ``steps`` and ``fpn_weights`` override the config's. Returns the final weights' path and the
    config used. InputError naming the file for a missing, invalid or other model's config."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}")
    config = Path(config)
    if not config.exists():
        raise InputError(config, "file not found")
    try:
        cfg = TrainConfig.from_file(config)
    except (ValueError, TypeError) as exc:
        raise InputError(config, f"invalid training config ({exc})") from exc
    if cfg.model != model:
        raise InputError(config, f"is a {cfg.model} config, not {model}")
    if steps is not None:
        cfg.steps = steps
    if fpn_weights is not None:
        cfg.fpn_weights = str(fpn_weights)
    resolved = resolve_device(device)
    out = Path(out)
    with atomic_path(out / "config.json") as tmp:
        tmp.write_text(json.dumps(cfg.to_dict(), indent=2) + "\n")
    runner = {"fpn": train_fpn, "afanet": train_afanet}.get(model) or baseline_module(model).train
    return runner(cfg, out, resolved, str(resume) if resume else None, progress=progress), cfg
