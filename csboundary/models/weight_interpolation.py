"""A fine-tuned FPN interpolated towards the weights it started from (weight-space ensembling,
as in WiSE-FT: Wortsman et al., "Robust fine-tuning of zero-shot models", CVPR 2022).

Why: fine-tuning the shipped FPN on dense synthetic cities makes it much better on dense-urban
photographs and worse on suburban ones (docs/real-imagery.md). Both networks start from the same
weights, so the straight line between them stays in a region of low loss, and a point on it
keeps most of each end's strength: the fine-tuned end's precision on flat roofs and parked cars,
and the starting end's recall on curbless suburban streets.
"""

from __future__ import annotations

from pathlib import Path

import torch

from csboundary.errors import InputError
from csboundary.models.checkpoint import file_sha256, load_checkpoint, save_checkpoint


def interpolate_state_dicts(
    start: dict[str, torch.Tensor], tuned: dict[str, torch.Tensor], alpha: float
) -> dict[str, torch.Tensor]:
    """``(1 - alpha) * start + alpha * tuned`` for every floating-point tensor (batch-norm
    statistics included); integer tensors (batch counts) are ``tuned``'s. Both must hold the same
    names and shapes."""
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must be in [0, 1], got {alpha}")
    if start.keys() != tuned.keys():
        raise ValueError(f"the two networks differ: {sorted(start.keys() ^ tuned.keys())[:5]}")
    out = {}
    for name, b in tuned.items():
        a = start[name]
        if a.shape != b.shape:
            raise ValueError(f"{name}: shape {tuple(a.shape)} against {tuple(b.shape)}")
        out[name] = torch.lerp(a.to(b.dtype), b, alpha) if b.is_floating_point() else b.clone()
    return out


def interpolate_fpn(start_path: str | Path, tuned_path: str | Path, alpha: float, out: str | Path) -> Path:
    """An ``fpn`` checkpoint at ``alpha`` from the FPN of ``start_path`` (a bundle or an fpn
    checkpoint) to the fine-tuned ``tuned_path``, with the tuned run's config and log and an
    ``interpolation`` record (both files, their sha256 and ``alpha``) as provenance."""
    start = load_checkpoint(start_path, ("bundle", "fpn"))
    tuned = load_checkpoint(tuned_path, ("fpn",))
    if start["fpn_config"] != tuned["fpn_config"]:
        raise InputError(
            tuned_path, f"its FPN is not built like {start_path}'s: interpolate only a fine-tune with its start"
        )
    try:
        weights = interpolate_state_dicts(start["fpn"], tuned["fpn"], alpha)
    except ValueError as exc:
        raise InputError(tuned_path, str(exc)) from exc
    record = {
        "start": str(start_path),
        "start_sha256": file_sha256(start_path),
        "tuned": str(tuned_path),
        "tuned_sha256": file_sha256(tuned_path),
        "alpha": alpha,
    }
    kept = {
        k: tuned[k]
        for k in ("code_version", "code_version_at_start", "train_config", "step", "validation")
        if k in tuned
    }
    return save_checkpoint(out, "fpn", fpn=weights, fpn_config=tuned["fpn_config"], interpolation=record, **kept)
