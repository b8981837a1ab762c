"""Commands that make models: training runs and the weights bundle that ships."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from csboundary.cli.options import DEVICE_HELP, finite, out_dir, out_file
from csboundary.errors import InputError


def train(
    model: str = typer.Argument(..., help="fpn | afanet | a baseline: orientation-refine | sat2graph | icurb."),
    config: Path = typer.Option(..., "--config", help="Training config JSON (see configs/)."),
    out: Path = typer.Option(..., "--out", help="Run folder: checkpoints, train.log."),
    resume: Optional[Path] = typer.Option(None, help="Checkpoint (*-last.pt) to resume from."),
    steps: Optional[int] = typer.Option(None, min=1, help="Override the config's step count."),
    fpn_weights: Optional[Path] = typer.Option(None, help="AfANet only: the trained FPN (overrides the config)."),
    device: str = typer.Option("auto", help=DEVICE_HELP),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Train the FPN, AfANet or a baseline on synthetic cities (built on first use under the config's cache)."""
    import json as _json

    from csboundary.data.atomic import atomic_path
    from csboundary.models.device import resolve_device
    from csboundary.models.baselines import METHODS, baseline_module
    from csboundary.models.train import TrainConfig, train_afanet, train_fpn

    if model not in ("fpn", "afanet", *METHODS):
        raise typer.BadParameter(f"model must be one of fpn, afanet, {', '.join(METHODS)}")
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
    out_dir(out)
    with atomic_path(out / "config.json") as tmp:
        tmp.write_text(_json.dumps(cfg.to_dict(), indent=2) + "\n")
    runner = {"fpn": train_fpn, "afanet": train_afanet}.get(model) or baseline_module(model).train
    weights = runner(cfg, out, resolved, str(resume) if resume else None, progress=not quiet)
    typer.echo(f"{weights}: trained {model} ({cfg.steps} steps); log in {out / 'train.log'}")


def bundle_weights(
    fpn: Path = typer.Option(..., help="Trained FPN checkpoint (fpn.pt)."),
    afanet: Path = typer.Option(..., help="Trained AfANet checkpoint (afanet.pt)."),
    out: Path = typer.Option(..., "--out", help="Bundle to write (e.g. csboundary/weights/csboundary-synthetic.pt)."),
    edge_threshold: float = typer.Option(0.5, callback=finite, min=0.0, max=1.0, help="Default adjacency probability for an edge."),
    min_edge_support: float = typer.Option(0.0, callback=finite, min=0.0, max=1.0, help="Default mean boundary probability along an AfANet edge (0 = no check)."),
    max_edge_length: float = typer.Option(0.0, callback=finite, min=0.0, help="Default longest AfANet edge in pixels (0 = no limit)."),
    grid_crossings: int = typer.Option(0, min=0, help="Add vertices where the boundary crosses grid lines this far apart (0 = off; 250 = the label grid)."),
) -> None:
    """Bundle a trained FPN and AfANet (weights + provenance) into one weights file."""
    from csboundary.models.bundle import make_bundle

    out_file(out, (".pt",))
    path = make_bundle(fpn, afanet, out, edge_threshold, min_support=min_edge_support, max_length_px=max_edge_length,
                       crossing_spacing_px=grid_crossings)
    typer.echo(f"{path}: {path.stat().st_size / 1e6:.1f} MB")
