"""Weights bundles: the FPN and AfANet a project run trained, in one file with their provenance.

The shipped weights are such a bundle. Beside the weights it records, for each model, the
training config, code version, step count and validation history, plus inference settings, so
``csboundary predict-patch`` needs only this one file.
"""

from __future__ import annotations

from pathlib import Path

from csboundary.data.units import MODEL_GSD
from csboundary.errors import InputError
from csboundary.models.checkpoint import load_checkpoint, save_checkpoint
from csboundary.models.training.config import training_pixel_size


def make_bundle(
    fpn_path: str | Path,
    afanet_path: str | Path,
    out: str | Path,
    edge_threshold: float = 0.5,
    max_degree: int = 2,
    min_support: float = 0.0,
    max_length_px: float = 0.0,
    crossing_spacing_px: int = 0,
    min_fragment_px: float = 0.0,
    vertex_threshold: float | None = None,
    max_gap_px: float = 0.0,
    gap_level: float = 0.3,
    fill_min_length_px: float = 0.0,
    surface_strong: float = 0.0,
    surface_weak: float = 0.2,
    surface_offset_px: float = 8.0,
    join_max_px: float = 0.0,
    attach_max_px: float = 0.0,
    join_attach_px: float = 0.0,
    surface_both_sides: float = 0.0,
    surface_gate_px: float = 0.0,
    outline_sure: float = 0.0,
) -> Path:
    """One weights file: both models, their provenance and the inference settings (vertex
    threshold: by default the one AfANet's training extracted its vertices at; edge threshold,
    degree cap, edge-support check (mean, length, longest gap), grid-crossing vertices, shortest fragment of the city graph,
    shortest skeleton stretch filled in, longest join between dangling ends, farthest line a dangling end of a window's
    graph is attached to over boundary, farthest line a dangling end of the city graph is attached to, road-surface check and its
    both-sides rule, surface gate of the maps, roadway outline (all three: an FPN with a surface head;
    :mod:`csboundary.graph.surface_gate`, :mod:`csboundary.graph.outline_fusion`);
    see :mod:`csboundary.graph.edge_support`, :mod:`csboundary.graph.crossings` and
    :mod:`csboundary.graph.fragments`, :mod:`csboundary.graph.skeleton_fill`,
    :mod:`csboundary.graph.end_joining`), and the pixel size the
    FPN was trained at (imagery is
    resampled to it)."""
    fpn = load_checkpoint(fpn_path, ("fpn",))
    afanet = load_checkpoint(afanet_path, ("afanet", "bundle"))
    keys = ("code_version", "code_version_at_start", "train_config", "step", "validation", "interpolation")
    if afanet["kind"] == "bundle":  # a bundle's AfANet, with the provenance that bundle recorded for it
        afanet = {
            "afanet": afanet["afanet"],
            "afanet_config": afanet["afanet_config"],
            **afanet["provenance"]["afanet"],
        }
    provenance = {name: {k: payload.get(k) for k in keys} for name, payload in (("fpn", fpn), ("afanet", afanet))}
    init = (fpn.get("train_config") or {}).get("init_fpn")
    if init and Path(init).exists():  # a fine-tuned FPN (e.g. a surface head on a trained one): where it started
        start = load_checkpoint(init, ("fpn", "bundle"))
        provenance["fpn_init"] = {
            "file": str(init),
            **(start["provenance"]["fpn"] if start["kind"] == "bundle" else {k: start.get(k) for k in keys}),
        }
    if (surface_strong > 0 or surface_gate_px > 0 or outline_sure > 0) and not (fpn["fpn_config"] or {}).get("surface"):
        raise InputError(fpn_path, "a surface check, gate or roadway outline needs an FPN with a road-surface head")
    pixel_size = training_pixel_size(fpn.get("train_config") or {}) or MODEL_GSD
    if vertex_threshold is None:
        vertex_threshold = float((afanet.get("train_config") or {}).get("vertex_threshold", 0.5))
    return save_checkpoint(
        out,
        "bundle",
        pixel_size_m=pixel_size,
        fpn=fpn["fpn"],
        fpn_config=fpn["fpn_config"],
        afanet=afanet["afanet"],
        afanet_config=afanet["afanet_config"],
        inference={
            "edge_threshold": edge_threshold,
            "max_degree": max_degree,
            "min_support": min_support,
            "max_length_px": max_length_px,
            "crossing_spacing_px": crossing_spacing_px,
            "min_fragment_px": min_fragment_px,
            "vertex_threshold": vertex_threshold,
            "max_gap_px": max_gap_px,
            "gap_level": gap_level,
            "fill_min_length_px": fill_min_length_px,
            **(
                {"join_max_px": join_max_px} if join_max_px > 0 else {}
            ),  # only when on: older readers know every other key
            **({"attach_max_px": attach_max_px} if attach_max_px > 0 else {}),
            **({"join_attach_px": join_attach_px} if join_attach_px > 0 else {}),
            **(
                {"surface_strong": surface_strong, "surface_weak": surface_weak, "surface_offset_px": surface_offset_px}
                if surface_strong > 0
                else {}
            ),
            **({"surface_both_sides": surface_both_sides} if surface_strong > 0 and surface_both_sides > 0 else {}),
            **({"surface_gate_px": surface_gate_px} if surface_gate_px > 0 else {}),
            **({"outline_sure": outline_sure} if outline_sure > 0 else {}),
        },
        provenance=provenance,
    )
