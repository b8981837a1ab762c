"""The loop every trainer shares (the FPN, AfANet, the baselines) and what a run keeps of itself:
seeding, the JSON-lines log, the learning-rate schedule, checkpoints and an exact resume."""

from __future__ import annotations

import json
import math
import random
import time
from dataclasses import dataclass, field
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


@dataclass
class TrainingRun:
    """One run's state, as the shared loop carries it: what is trained (``kind`` names its files and
    checkpoint keys; ``model`` and its ``model_config``), how (``config``, ``optimizer``, ``rng``),
    where it writes (``out_dir``, ``log``) and how far it has got (``step``, the validation
    ``history``)."""

    kind: str
    model: torch.nn.Module
    model_config: Any
    config: TrainConfig
    out_dir: Path
    optimizer: torch.optim.Optimizer
    rng: np.random.Generator
    log: RunLog
    step: int = 0
    history: list = field(default_factory=list)

    def resumed(self, checkpoint: str | None) -> "TrainingRun":
        """This run continued exactly from the checkpoint ``checkpoint`` (weights, optimizer and
        every random stream restored; its step and history taken); unchanged without one."""
        self.step, self.history = resume_run(checkpoint, self.kind, self.model, self.optimizer, self.rng)
        return self

    def record(self, metrics: dict) -> None:
        """Log one validation and write the resumable ``<kind>-last.pt`` (and a snapshot when asked)."""
        self.history.append(metrics)
        self.log.write(event="validate", **metrics)
        self.save(self.out_dir / f"{self.kind}-last.pt", resumable=True)
        if self.config.snapshots:
            self.save(self.out_dir / f"{self.kind}-step{self.step}.pt", resumable=False)

    def finish(self) -> Path:
        """Write the final ``<kind>.pt`` (no optimizer state) and log its path."""
        final = self.out_dir / f"{self.kind}.pt"
        self.save(final, resumable=False)
        self.log.write(event="done", step=self.step, weights=str(final))
        return final

    def save(self, path: Path, resumable: bool) -> None:
        """The weights, their configs and the run's progress; ``resumable`` adds the optimizer and
        every random stream, so the run can continue exactly."""
        content = {
            self.kind: self.model.state_dict(),
            f"{self.kind}_config": self.model_config.to_dict(),
            "train_config": self.config.to_dict(),
            "step": self.step,
            "validation": self.history,
            "code_version_at_start": _RUN_CODE_VERSION.get("at_start", code_version()),
        }
        if resumable:
            content["optimizer"] = self.optimizer.state_dict()
            content["torch_rng"] = torch.get_rng_state()
            content["numpy_rng"] = self.rng.bit_generator.state
            if torch.cuda.is_available():
                content["cuda_rng"] = torch.cuda.get_rng_state_all()
        save_checkpoint(path, self.kind, **content)


def optimize(run: TrainingRun, loss_at, validate, progress: bool = True) -> Path:
    """The loop every trainer shares (the FPN, AfANet, the dense baselines): cosine learning
    rate, one optimizer step per ``loss_at(step) -> (loss, extras)`` (a ``None`` loss, e.g. an
    AfANet window with fewer than two vertices, counts the step without an update), a validation
    (``validate(step) -> dict``, logged with the extras) and a resumable checkpoint every
    ``validate_every`` steps, the final weights at the end."""
    config, optimizer = run.config, run.optimizer
    run.model.train()
    bar = tqdm(total=config.steps, initial=run.step, desc=f"train {run.kind}", unit="step", disable=not progress)
    last = None
    while run.step < config.steps:
        lr = _cosine_lr(config, run.step)
        for group in optimizer.param_groups:
            group["lr"] = lr * group.get("lr_scale", 1.0)
        loss, extras = loss_at(run.step)
        if loss is not None:
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            last = loss.item()
        run.step += 1
        bar.update(1)
        if last is not None:
            bar.set_postfix(
                loss=f"{last:.4f}", **{k: f"{v:.3g}" if isinstance(v, float) else v for k, v in extras.items()}
            )
        if run.step % config.validate_every == 0 or run.step == config.steps:
            run.record({"step": run.step, "train_loss": last, "lr": lr, **extras, **validate(run.step)})
    bar.close()
    return run.finish()


def _cosine_lr(config: TrainConfig, step: int) -> float:
    """Short linear warm-up, then cosine decay to 5% of the base rate."""
    warm = max(1, config.steps // 50)
    if step < warm:
        return config.lr * (step + 1) / warm
    t = (step - warm) / max(1, config.steps - warm)
    return config.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(1.0, t))))


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
