"""Weights bundles: the FPN and AfANet a project run trained, in one file with their provenance.

The shipped weights are such a bundle. Beside the weights it records, for each model, the
training config, code version, step count and validation history, plus inference settings, so
``csboundary predict-patch`` needs only this one file.
"""

from __future__ import annotations

from pathlib import Path

from csboundary.data.units import MODEL_GSD
from csboundary.errors import InputError
from csboundary.graph.settings import GraphSettings
from csboundary.models.checkpoint import load_checkpoint, save_checkpoint
from csboundary.models.training.config import training_pixel_size


def make_bundle(
    fpn_path: str | Path, afanet_path: str | Path, out: str | Path, settings: GraphSettings | None = None
) -> Path:
    """One weights file: both models, their provenance, the graph ``settings`` every prediction
    with it uses (:class:`~csboundary.graph.settings.GraphSettings`, written by their names; default:
    every optional step off and the vertex threshold AfANet's training extracted its vertices at)
    and the pixel size the FPN was trained at (imagery is resampled to it). A surface check, gate
    or roadway outline needs an FPN with a road-surface head."""
    fpn = load_checkpoint(fpn_path, ("fpn",))
    afanet = afanet_checkpoint(afanet_path)
    keys = ("code_version", "code_version_at_start", "train_config", "step", "validation", "interpolation")
    provenance = {name: {k: payload.get(k) for k in keys} for name, payload in (("fpn", fpn), ("afanet", afanet))}
    init = (fpn.get("train_config") or {}).get("init_fpn")
    if init and Path(init).exists():  # a fine-tuned FPN (e.g. a surface head on a trained one): where it started
        start = load_checkpoint(init, ("fpn", "bundle"))
        provenance["fpn_init"] = {
            "file": str(init),
            **(start["provenance"]["fpn"] if start["kind"] == "bundle" else {k: start.get(k) for k in keys}),
        }
    if settings is None:
        settings = GraphSettings().replaced(vertex_threshold=trained_vertex_threshold(afanet))
    if settings.reads_surface and not (fpn["fpn_config"] or {}).get("surface"):
        raise InputError(fpn_path, "a surface check, gate or roadway outline needs an FPN with a road-surface head")
    pixel_size = training_pixel_size(fpn.get("train_config") or {}) or MODEL_GSD
    return save_checkpoint(
        out,
        "bundle",
        pixel_size_m=pixel_size,
        fpn=fpn["fpn"],
        fpn_config=fpn["fpn_config"],
        afanet=afanet["afanet"],
        afanet_config=afanet["afanet_config"],
        inference=settings.to_bundle(),
        provenance=provenance,
    )


def afanet_checkpoint(path: str | Path) -> dict:
    """An AfANet checkpoint, or a bundle's AfANet with the provenance that bundle recorded for it."""
    afanet = load_checkpoint(path, ("afanet", "bundle"))
    if afanet["kind"] == "bundle":
        afanet = {
            "afanet": afanet["afanet"],
            "afanet_config": afanet["afanet_config"],
            **afanet["provenance"]["afanet"],
        }
    return afanet


def trained_vertex_threshold(afanet: dict) -> float:
    """The keypoint threshold an AfANet checkpoint's training extracted its vertices at (0.5 unless
    its config says)."""
    return float((afanet.get("train_config") or {}).get("vertex_threshold", 0.5))
