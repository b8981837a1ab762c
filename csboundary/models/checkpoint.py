"""Checkpoints: weights plus everything needed to trust and reproduce them.

A checkpoint is a ``torch.save`` dict with ``format``, ``kind`` (fpn | afanet | bundle), the
model config, the training config, step, validation metrics, code version and, while training,
optimizer and RNG states (so a run resumes exactly). Shipped weights are a ``bundle`` holding
both models without optimizer state.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import torch

from csboundary import __version__
from csboundary.data.atomic import atomic_path
from csboundary.errors import InputError

FORMAT = "csboundary-checkpoint"


def code_version() -> str:
    """Package version plus the git commit when running from a checkout."""
    try:
        root = Path(__file__).resolve().parents[2]
        sha = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=5).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True, timeout=5).stdout.strip()
        return f"{__version__}+{sha}{'.dirty' if dirty else ''}" if sha else __version__
    except (OSError, subprocess.SubprocessError):
        return __version__


def save_checkpoint(path: str | Path, kind: str, **content: Any) -> Path:
    payload = {"format": FORMAT, "kind": kind, "code_version": code_version(), **content}
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return Path(path)


def load_fpn(source: str | Path | dict, device: torch.device | str = "cpu"):
    """csBoundary's FPN, in eval mode on ``device``, from an ``fpn`` checkpoint or a bundle (a
    path, or a payload already loaded)."""
    from csboundary.models.fpn import fpn_for_weights

    payload = source if isinstance(source, dict) else load_checkpoint(source, ("fpn", "bundle"), map_location=device)
    fpn = fpn_for_weights(payload["fpn_config"]).to(device).eval().to(memory_format=torch.channels_last)
    fpn.load_state_dict(payload["fpn"])
    return fpn


def load_checkpoint(path: str | Path, kinds: tuple[str, ...], map_location="cpu") -> dict[str, Any]:
    """Load a checkpoint and check that it holds one of ``kinds``; errors name the file."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "weights file not found")
    try:
        payload = torch.load(path, map_location=map_location, weights_only=False)
    except Exception as exc:  # torch raises many types for foreign or damaged files
        raise InputError(path, f"not a readable weights file ({type(exc).__name__})") from exc
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise InputError(path, "not a csboundary weights file")
    if payload.get("kind") not in kinds:
        raise InputError(path, f"holds a {payload.get('kind')!r} model; expected {' or '.join(kinds)}")
    return payload
