"""The loop every trainer shares (the FPN, AfANet, the baselines) and what a run keeps of itself:
seeding, the JSON-lines log, the learning-rate schedule, checkpoints and an exact resume."""

from __future__ import annotations

import json
import math
import random
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from csboundary.models.checkpoint import code_version, load_checkpoint, save_checkpoint
from csboundary.models.training.config import TrainConfig


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


def run_code_version() -> str:
    """The code version stamped by :func:`seed_everything` at the start of this run."""
    return _RUN_CODE_VERSION["at_start"]


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


def optimize(
    kind: str,
    model,
    model_config,
    config: TrainConfig,
    out_dir: Path,
    optimizer,
    rng: np.random.Generator,
    step: int,
    history: list,
    log: RunLog,
    loss_at,
    validate,
    progress: bool = True,
) -> Path:
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
            bar.set_postfix(
                loss=f"{last:.4f}", **{k: f"{v:.3g}" if isinstance(v, float) else v for k, v in extras.items()}
            )
        if step % config.validate_every == 0 or step == config.steps:
            metrics = {"step": step, "train_loss": last, "lr": lr, **extras, **validate(step)}
            _record(out_dir, kind, metrics, model, model_config, config, step, history, optimizer, rng, log)
    bar.close()
    return _finish(out_dir, kind, model, model_config, config, step, history, log)


def _cosine_lr(config: TrainConfig, step: int) -> float:
    """Short linear warm-up, then cosine decay to 5% of the base rate."""
    warm = max(1, config.steps // 50)
    if step < warm:
        return config.lr * (step + 1) / warm
    t = (step - warm) / max(1, config.steps - warm)
    return config.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(1.0, t))))


def _record(
    out_dir: Path, kind: str, metrics: dict, model, model_config, config, step, history, optimizer, rng, log: RunLog
) -> None:
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


def _save(
    path: Path, kind: str, model, model_config, config: TrainConfig, step: int, history: list, optimizer, rng=None
) -> None:
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


def resume_run(resume: str | None, kind: str, model, optimizer, rng: np.random.Generator) -> tuple[int, list]:
    """Restore weights, optimizer and every random stream from the checkpoint ``resume``, so a
    resumed run continues exactly: its (step, validation history); (0, []) without one."""
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
