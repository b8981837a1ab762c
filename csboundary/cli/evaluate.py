"""``csboundary evaluate``: score a predicted boundary graph against the ground truth."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Optional

import typer

from csboundary.cli.options import finite


def evaluate(
    pred: Path = typer.Argument(..., help="Predicted boundaries: csboundary graph JSON, GeoPackage or GeoJSON LineStrings."),
    gt: Path = typer.Argument(..., help="Ground truth: graph JSON, GeoPackage/GeoJSON, or a city directory (its ground_truth.gpkg and tiles)."),
    scale: str = typer.Option("city", help="city (whole graphs) | patch (1000 px patch cores, averaged)."),
    apls: str = typer.Option("paper", help="APLS variant: paper (Topo-boundary/csBoundary) | symmetric (SpaceNet style)."),
    seed: int = typer.Option(0, min=0, help="Seed of the sampled vertex pairs; equal seeds give identical results."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Also write every number (and per-patch scores) to this JSON file."),
    raster: Optional[Path] = typer.Option(None, help="City directory, GeoTIFF(s) or tile directory whose pixel grid is the frame (world -> pixels)."),
    gsd: Optional[float] = typer.Option(None, callback=finite, help="Without a raster: pixel size (world units) of a frame at the inputs' top-left corner."),
    pixels: bool = typer.Option(False, "--pixels", help="The inputs' coordinates are pixels (col, row), not world coordinates."),
    tau: str = typer.Option("2,5,10", help="Relaxation radii in pixels for precision/recall/F1, comma-separated."),
) -> None:
    """Relaxed precision/recall/F1, APLS and TLTS of PRED against GT (definitions: docs/metrics.md)."""
    if scale not in ("city", "patch"):
        raise typer.BadParameter("must be city or patch", param_hint="--scale")
    if apls not in ("paper", "symmetric"):
        raise typer.BadParameter("must be paper or symmetric", param_hint="--apls")
    from csboundary.metrics import MetricConfig
    from csboundary.metrics import evaluate as run_metrics
    from csboundary.errors import InputError
    from csboundary.metrics.io import grid_for, load_pair
    from csboundary.metrics.sampling import RasterTooLarge

    try:
        taus = tuple(float(v) for v in tau.split(","))
        config = MetricConfig(taus=taus)
    except ValueError:
        raise typer.BadParameter(f"expected positive numbers such as 2,5,10, got {tau!r}", param_hint="--tau")
    if gsd is not None and not (math.isfinite(gsd) and gsd > 0):
        raise typer.BadParameter(f"must be a positive number, got {gsd}", param_hint="--gsd")
    if json_out is not None:
        from csboundary.data.atomic import check_output_file

        check_output_file(json_out, (".json",))
    pred_graph, gt_graph, frame = load_pair(pred, gt, raster=raster, gsd=gsd, pixels=pixels)
    grid = grid_for(frame, pred_graph, gt_graph) if scale == "patch" else None
    extent = (0, 0, frame.width, frame.height) if frame.width else None
    try:
        result = run_metrics(pred_graph, gt_graph, scale=scale, grid=grid, apls=apls, seed=seed, config=config, extent=extent)
    except RasterTooLarge as exc:
        raise InputError(f"{pred} / {gt}", f"{exc}; give --raster to clip to the imagery") from exc
    result["inputs"] = {"pred": str(pred), "gt": str(gt), "frame": frame.source, "crs": frame.crs}
    typer.echo(format_table(result))
    if json_out is not None:
        write_scores(json_out, result)
        typer.echo(f"wrote {json_out}")


def write_scores(path: Path, result: dict) -> None:
    """Scores as JSON, atomically; undefined metrics (NaN) become null."""
    from csboundary.data.atomic import atomic_path
    from csboundary.metrics.aggregate import nan_to_none

    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(nan_to_none(result), indent=1, default=float) + "\n")


def _num(value: float, digits: int = 4) -> str:
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}"


def format_table(result: dict) -> str:
    """A readable summary of :func:`csboundary.metrics.evaluate`'s result."""
    m, c = result["metrics"], result["counts"]
    taus = result["config"]["taus"]
    head = f"{result['inputs']['pred']} vs {result['inputs']['gt']}: {result['scale']} scale, APLS {result['apls_variant']}, seed {result['seed']}"
    if result["scale"] == "patch":
        head += f"\n{c['patches_scored']} of {c['patches']} patches scored ({c['patches_with_gt']} with ground truth); per-patch means"
    lines = [head, f"{'':12s}" + "".join(f"{'tau=' + format(t, 'g'):>10s}" for t in taus)]
    for label, key in (("precision", "precision"), ("recall", "recall"), ("F1", "f1")):
        lines.append(f"{label:12s}" + "".join(f"{_num(m[f'{key}@{t:g}']):>10s}" for t in taus))
    apls_line = f"{'APLS':12s}{_num(m['apls']):>10s}   {result['apls_variant']}"
    if result["apls_variant"] == "symmetric":
        apls_line += f": gt->pred {_num(m['apls_gt_to_pred'])}, pred->gt {_num(m['apls_pred_to_gt'])}"
    lines.append(apls_line)
    lines.append(f"{'TLTS':12s}{_num(m['tlts']):>10s}   too long {_num(m['tlts_too_long'])}, too short {_num(m['tlts_too_short'])}, "
                 f"infeasible {_num(m['tlts_infeasible'])}")
    lines.append(f"{c['pairs']} sampled pairs (phi {result['config']['phi']:g}, snap < {result['config']['snap_radius']:g} px)")
    return "\n".join(lines)


def format_rows(results: dict[str, dict]) -> str:
    """Several results side by side, one row each (the shape of the paper's tables)."""
    first = next(iter(results.values()))
    taus = [f"{t:g}" for t in first["config"]["taus"]]
    columns = [f"{k}@{t}" for k in ("precision", "recall", "f1") for t in taus] + ["apls", "tlts"]
    header = ["P@" + t for t in taus] + ["R@" + t for t in taus] + ["F1@" + t for t in taus] + ["APLS", "TLTS"]
    width = max(12, *(len(k) + 2 for k in results))
    lines = [f"{'':{width}s}" + "".join(f"{h:>8s}" for h in header)]
    for label, result in results.items():
        m = result["metrics"]
        lines.append(f"{label:{width}s}" + "".join(f"{_num(m[c], 3):>8s}" for c in columns))
    return "\n".join(lines)
