"""Commands that score: a prediction against ground truth, a model on a city or on a set of
labelled cities, and the paper's comparison of methods."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import typer

from csboundary.cli.options import (
    DeviceOption,
    EngineOption,
    PrecisionOption,
    QuietOption,
    WeightsOption,
    finite,
    out_dir,
    out_file,
    readable_inputs,
    with_graph_options,
)
from csboundary.graph.settings import GraphOverrides


def evaluate(
    pred: Path = typer.Argument(
        ..., help="Predicted boundaries: csboundary graph JSON, GeoPackage or GeoJSON LineStrings."
    ),
    gt: Path = typer.Argument(
        ..., help="Ground truth: graph JSON, GeoPackage/GeoJSON, or a city directory (its ground_truth.gpkg and tiles)."
    ),
    scale: str = typer.Option("city", help="city (whole graphs) | patch (1000 px patch cores, averaged)."),
    apls: str = typer.Option(
        "paper", help="APLS variant: paper (Topo-boundary/csBoundary) | symmetric (SpaceNet style)."
    ),
    seed: int = typer.Option(0, min=0, help="Seed of the sampled vertex pairs; equal seeds give identical results."),
    json_out: Optional[Path] = typer.Option(
        None, "--json", help="Also write every number (and per-patch scores) to this JSON file."
    ),
    raster: Optional[Path] = typer.Option(
        None, help="City directory, GeoTIFF(s) or tile directory whose pixel grid is the frame (world -> pixels)."
    ),
    gsd: Optional[float] = typer.Option(
        None,
        callback=finite,
        help="Without a raster: pixel size (world units) of a frame at the inputs' top-left corner.",
    ),
    pixels: bool = typer.Option(
        False, "--pixels", help="The inputs' coordinates are pixels (col, row), not world coordinates."
    ),
    tau: str = typer.Option("2,5,10", help="Relaxation radii in pixels for precision/recall/F1, comma-separated."),
) -> None:
    """Relaxed precision/recall/F1, APLS and TLTS of PRED against GT (definitions: docs/metrics.md)."""
    if scale not in ("city", "patch"):
        raise typer.BadParameter("must be city or patch", param_hint="--scale")
    if apls not in ("paper", "symmetric"):
        raise typer.BadParameter("must be paper or symmetric", param_hint="--apls")
    from csboundary.errors import InputError
    from csboundary.metrics import MetricConfig
    from csboundary.metrics import evaluate as run_metrics
    from csboundary.metrics.io import frame_metres_per_px, grid_for, load_pair
    from csboundary.metrics.report import format_table, write_scores
    from csboundary.metrics.sampling import RasterTooLarge

    try:
        taus = tuple(float(v) for v in tau.split(","))
        config = MetricConfig(taus=taus)
    except ValueError:
        raise typer.BadParameter(f"expected positive numbers such as 2,5,10, got {tau!r}", param_hint="--tau") from None
    if gsd is not None and not (math.isfinite(gsd) and gsd > 0):
        raise typer.BadParameter(f"must be a positive number, got {gsd}", param_hint="--gsd")
    if json_out is not None:
        from csboundary.data.atomic import check_output_file

        check_output_file(json_out, (".json",))
    pred_graph, gt_graph, frame = load_pair(pred, gt, raster=raster, gsd=gsd, pixels=pixels)
    grid = grid_for(frame, pred_graph, gt_graph) if scale == "patch" else None
    extent = (0, 0, frame.width, frame.height) if frame.width else None
    try:
        result = run_metrics(
            pred_graph,
            gt_graph,
            scale=scale,
            grid=grid,
            apls=apls,
            seed=seed,
            config=config,
            extent=extent,
            metres_per_px=frame_metres_per_px(frame),
        )
    except RasterTooLarge as exc:
        if extent is None:  # nothing says where the imagery is: a raster would cut the lines to it
            raise InputError(f"{pred} / {gt}", f"{exc}; give --raster to clip to the imagery") from exc
        raise InputError(
            f"{pred} / {gt}",
            f"{exc.size} within the imagery {frame.source}: more than the metrics take at once; "
            "evaluate a smaller part of it",
        ) from exc
    result["inputs"] = {"pred": str(pred), "gt": str(gt), "frame": frame.source, "crs": frame.crs}
    typer.echo(format_table(result))
    if json_out is not None:
        write_scores(json_out, result)
        typer.echo(f"wrote {json_out}")


@with_graph_options
def evaluate_model(
    city: Path = typer.Argument(..., help="A city directory with ground truth (e.g. a valid-split synthetic city)."),
    weights: WeightsOption = None,
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the results as JSON here."),
    seed: int = typer.Option(0, help="Seed of the APLS/TLTS pair sampling."),
    graph: GraphOverrides = GraphOverrides(),
    batch_size: int = typer.Option(1, min=1, help="Patches per FPN batch."),
    engine: EngineOption = "auto",
    precision: PrecisionOption = "auto",
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """Evaluate a model on a city at patch scale (each patch's graph on its core) and city scale
    (the stitched graph), without writing the prediction."""
    if json_out is not None:
        out_file(json_out, (".json",))
    readable_inputs([city])
    from csboundary.metrics.report import format_rows, write_scores
    from csboundary.pipeline.prediction.city_scores import evaluate_city
    from csboundary.pipeline.prediction.patch import load_predictor

    predictor = load_predictor(weights, device, graph, engine=engine, precision=precision)
    scores = evaluate_city(city, predictor, seed, batch_size=batch_size, progress=not quiet)
    for item in scores.values():
        item["inputs"]["pred"] = f"{weights or 'shipped weights'} on {city}"
    typer.echo(format_rows(scores))
    if json_out is not None:
        write_scores(json_out, scores)


@with_graph_options
def evaluate_set_cmd(
    set_dir: Path = typer.Argument(..., help="A folder of labelled cities (import-masks output, or city directories)."),
    weights: WeightsOption = None,
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write per-city and mean scores as JSON here."),
    seed: int = typer.Option(0, help="Seed of the APLS/TLTS pair sampling."),
    graph: GraphOverrides = GraphOverrides(),
    engine: EngineOption = "auto",
    precision: PrecisionOption = "auto",
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """Score a model on every city of a validation set (city scale) and print the per-city and
    mean scores: how to select and compare models on real labelled imagery."""
    from csboundary.metrics.report import write_scores
    from csboundary.pipeline.evaluation.evaluate_set import evaluate_set, format_set
    from csboundary.pipeline.prediction.patch import load_predictor

    if json_out is not None:
        out_file(json_out, (".json",))
    predictor = load_predictor(weights, device, graph, engine=engine, precision=precision)
    result = evaluate_set(set_dir, predictor, seed=seed, progress=not quiet)
    result["weights"] = str(weights or "shipped")
    typer.echo(format_set(result))
    if json_out is not None:
        write_scores(json_out, result)


def benchmark(
    out: Path = typer.Option(
        Path("docs/benchmark"),
        help="Folder for tables.md, table*.csv, fig7-comparison.png, benchmark.json, predictions/.",
    ),
    city: Optional[Path] = typer.Option(
        None,
        help="Test city with ground truth (default: the test-split city seed 1, 1x1 tile of 5000 px, "
        "built on first use).",
    ),
    weights_dir: Optional[Path] = typer.Option(None, help="Weights folder (default: the package's shipped weights)."),
    methods: Optional[str] = typer.Option(
        None,
        help="Comma-separated subset of: " + "csboundary, orientation-refine, sat2graph, icurb, "
        "ablation-full, no-global, no-local.",
    ),
    seed: int = typer.Option(0, help="Seed of the APLS/TLTS pair sampling."),
    device: DeviceOption = "auto",
    quiet: bool = typer.Option(False, help="No progress bars."),
) -> None:
    """The paper's comparison (Tables I-IV, Fig. 7): every method predicts one test city through the
    same pipeline and metrics; training times come from the logs beside the weights."""
    from csboundary.models.device import resolve_device
    from csboundary.pipeline.evaluation.benchmark import benchmark_to_folder, unknown_methods

    chosen = [m.strip() for m in methods.split(",")] if methods else None
    if unknown_methods(chosen):
        raise typer.BadParameter(f"unknown method(s) {', '.join(unknown_methods(chosen))}", param_hint="--methods")
    out_dir(out)
    benchmark_to_folder(out, city, weights_dir, resolve_device(device), chosen, seed, progress=not quiet)
    typer.echo((out / "tables.md").read_text())
