"""Commands that predict boundaries, and what follows a prediction: a Lanelet2 map, a review
page, a reviewer's edits merged back, and the demo that shows it all on a synthetic city."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Optional

import numpy as np
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
    parse_numbers,
    positive,
    readable_inputs,
    with_graph_options,
)
from csboundary.errors import InputError, InputWarning
from csboundary.graph.settings import GraphOverrides


@with_graph_options
def predict(
    inputs: list[Path] = typer.Argument(
        ..., metavar="IMAGERY...", help="GeoTIFF tile(s), a directory of tiles, or a city directory."
    ),
    out: Path = typer.Option(
        ..., "--out", help="Output folder (boundaries.gpkg/.geojson, graph.json, PNGs, summary.json)."
    ),
    weights: WeightsOption = None,
    graph: GraphOverrides = GraphOverrides(),
    batch_size: int = typer.Option(
        1, min=1, help="Patches per FPN batch (more is faster on a GPU, needs more memory)."
    ),
    write_maps: bool = typer.Option(
        False, "--write-maps", help="Also write the stitched probability maps as a Cloud-Optimized GeoTIFF (maps.tif)."
    ),
    lanelet2: bool = typer.Option(
        False, "--lanelet2", help="Also write the boundaries as a Lanelet2 map (map.osm + map_projector_info.yaml)."
    ),
    gsd: Optional[float] = typer.Option(
        None, callback=positive, help="Pixel size in metres of imagery without a CRS (needed then)."
    ),
    restart: bool = typer.Option(
        False, "--restart", help="Discard the unfinished run in --out instead of resuming it."
    ),
    scheduler: Optional[str] = typer.Option(
        None, help="Run on this Dask cluster (tcp://HOST:8786); --out must be on a filesystem its workers share."
    ),
    workers: Optional[int] = typer.Option(
        None, min=1, help="Run on a local Dask cluster of this many worker processes."
    ),
    threads: Optional[int] = typer.Option(
        None, min=1, help="Torch threads per process (default: all cores; with --workers N, cores / N)."
    ),
    engine: EngineOption = "auto",
    precision: PrecisionOption = "auto",
    device: DeviceOption = "auto",
    quiet: QuietOption = False,
) -> None:
    """City-scale prediction: patch grid -> FPN -> averaged maps -> vertices -> AfANet -> stitched
    city graph, written in the input's CRS. Any pixel size from 0.03 to 1 m, any CRS (metres,
    feet, degrees) and 8/16-bit or float imagery are resampled and stretched on the fly
    (docs/city-inference.md). Work is kept as it is done: the same command after an interruption
    continues where it stopped (docs/scaling.md)."""
    if scheduler and workers:
        raise typer.BadParameter("give --scheduler or --workers, not both")
    readable_inputs(inputs)
    out_dir(out, inputs)
    from csboundary.pipeline.jobs.predict import predict_to_folder
    from csboundary.pipeline.outputs.run_summary import counted, stage_table, written_files
    from csboundary.pipeline.prediction.options import PredictionOptions
    from csboundary.pipeline.prediction.patch import load_predictor

    predictor = load_predictor(weights, device, graph, engine=engine, precision=precision)

    def announce(plan, view) -> None:
        where = (
            f"({plan.n_rows}x{plan.n_cols})"
            if plan.planned is None
            else f"under {counted(len(view.mosaic.footprint), 'group')} of tiles kilometres apart, "
            f"of a {plan.n_rows}x{plan.n_cols} grid"
        )
        typer.echo(
            f"{out}: {counted(len(plan), 'patch')} {where} over {view.mosaic.width}x{view.mosaic.height} px "
            f"at {predictor.pixel_size_m:g} m; FPN in {predictor.precision_choice or predictor.precision}",
            err=True,
        )

    options = PredictionOptions(
        gsd=gsd,
        batch_size=batch_size,
        threads=threads,
        scheduler=scheduler,
        workers=workers,
        write_maps=write_maps,
        lanelet2=lanelet2,
        restart=restart,
        progress=not quiet,
    )
    summary = predict_to_folder(inputs, out, predictor, options, weights=weights, on_plan=announce)
    c = summary["counts"]
    typer.echo(
        f"{out}: {counted(c['edges'], 'edge')}, {counted(c['vertices'], 'vertex', 'vertices')}, {c['boundary_km']} km of boundary\n"
        f"{stage_table(summary)}\nwrote {out}: {written_files(out)}"
    )


@with_graph_options
def predict_patch(
    image: Path = typer.Argument(
        ..., help="One image: a GeoTIFF (or any raster) of at most 1100x1100 px, 4 bands (or RGB)."
    ),
    out: Path = typer.Option(..., "--out", help="Output folder: graph.json, boundaries.geojson, overlay.png."),
    weights: Optional[Path] = typer.Option(
        None, help="Weights bundle (default: the shipped weights) or an AfANet checkpoint."
    ),
    fpn_weights: Optional[Path] = typer.Option(None, help="FPN checkpoint, when --weights is an AfANet checkpoint."),
    graph: GraphOverrides = GraphOverrides(),
    gsd: Optional[float] = typer.Option(
        None, callback=positive, help="Pixel size in metres of an image without a CRS."
    ),
    engine: EngineOption = "auto",
    precision: PrecisionOption = "auto",
    device: DeviceOption = "auto",
) -> None:
    """Predict the road-boundary graph of one image of at most 1100x1100 px exactly as `predict`
    predicts it (same patch grid, maps, post-processing and graph), with an overlay picture of
    the maps and the graph over the image."""
    out_dir(out, [image] if image.is_dir() else [])
    readable_inputs([image])
    from csboundary.pipeline.jobs.predict import predict_patch_to_folder
    from csboundary.pipeline.prediction.patch import load_predictor

    predictor = load_predictor(weights, device, graph, fpn_weights=fpn_weights, engine=engine, precision=precision)
    drawn = predict_patch_to_folder(image, out, predictor, gsd)
    kinds = drawn.edge_kinds or []
    typer.echo(
        f"{out}: {drawn.n_vertices} vertices, {drawn.n_edges} edges ({kinds.count('corner')} corner, "
        f"{kinds.count('skeleton')} filled in from the segmentation)"
    )


BOUNDS_HELP = (
    "One district: MINX,MINY,MAXX,MAXY in the prediction's CRS; the edges meeting it are read from the GeoPackage's "
    "spatial index, so a city of any size is handled a district at a time."
)


def district_bounds(text: str | None) -> tuple[float, float, float, float] | None:
    if text is None:
        return None
    x0, y0, x1, y1 = parse_numbers(text, 4, "--bounds", "MINX,MINY,MAXX,MAXY")
    if not (x0 < x1 and y0 < y1):
        raise typer.BadParameter(f"{text!r}: need MINX < MAXX and MINY < MAXY", param_hint="--bounds")
    return x0, y0, x1, y1


def export_lanelet2(
    prediction: Path = typer.Argument(..., help="A predict output folder (its graph.json), or a graph.json file."),
    out: Path = typer.Option(..., "--out", help="Lanelet2 OSM file to write; map_projector_info.yaml goes beside it."),
    origin: Optional[str] = typer.Option(
        None, help="Projection origin LAT,LON (default: the middle of the boundaries)."
    ),
    bounds: Optional[str] = typer.Option(None, help=BOUNDS_HELP),
    min_confidence: Optional[float] = typer.Option(
        None,
        "--min-confidence",
        callback=finite,
        min=0.0,
        max=1.0,
        help="Leave out the edges whose confidence is below this (0 = keep all).",
    ),
) -> None:
    """The predicted boundaries as a Lanelet2 map: one road_border linestring per boundary (closed
    loops closed), confidence as an attribute, UTM projector around the origin (Autoware's
    map_projector_info.yaml beside it). With --bounds, one district of the city; with
    --min-confidence, only the edges at least that sure."""
    from csboundary.pipeline.outputs.lanelet2_export import write_lanelet2
    from csboundary.pipeline.outputs.prediction_reader import read_prediction_graph

    source = prediction / "graph.json" if prediction.is_dir() and bounds is None else prediction
    box = district_bounds(bounds)
    out_file(out, (".osm",))
    at = None
    if origin is not None:
        lat, lon = parse_numbers(origin, 2, "--origin", "LAT,LON")
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            raise typer.BadParameter(f"{origin!r} is not a latitude,longitude", param_hint="--origin")
        at = (lat, lon)
    from csboundary.pipeline.outputs.prediction_files import check_finite_geometry

    graph = read_prediction_graph(source, box)
    check_finite_geometry(graph, source)
    if min_confidence:
        if graph.n_edges and (graph.edge_scores is None or not np.isfinite(graph.edge_scores).all()):
            raise InputError(
                source, "its edges carry no confidence to compare with --min-confidence (predicted without one)"
            )
        if not predicted_with_confidence(prediction):
            raise InputError(
                source,
                "was predicted with weights that have no edge confidence: its scores are the network's, not "
                "calibrated probabilities, so --min-confidence would filter on them (fit-confidence, then "
                "predict again)",
            )
        kept = graph.edge_subgraph(graph.edge_scores >= min_confidence) if graph.n_edges else graph
        typer.echo(f"--min-confidence {min_confidence:g}: {kept.n_edges} of {graph.n_edges} edges kept")
        graph = kept
    if graph.n_edges == 0:
        where = " in --bounds" if box else ""
        warnings.warn(f"{source}: no boundary to export{where}; the map is empty", InputWarning, stacklevel=2)
    written = write_lanelet2(graph, out, at)
    typer.echo(
        f"{out}: {written['linestrings']} road_border linestrings; origin {written['origin'][0]:.7f},{written['origin'][1]:.7f} "
        f"in {written['projector_info']}"
    )


def predicted_with_confidence(prediction: Path) -> bool:
    """False when the prediction's summary says its bundle had no edge confidence (its scores are
    then the networks'); True otherwise, and for predictions of builds that did not say."""
    import json

    summary = (prediction if prediction.is_dir() else prediction.parent) / "summary.json"
    try:
        return json.loads(summary.read_text()).get("settings", {}).get("edge_confidence", True) is not False
    except (OSError, ValueError, AttributeError):
        return True


def review(
    prediction: Path = typer.Argument(..., help="A predict output folder."),
    out: Optional[Path] = typer.Option(None, "--out", help="Folder of the page (default: PREDICTION/review)."),
    ground_truth: Optional[Path] = typer.Option(
        None, help="Boundaries to show as a toggle (default: the city's own, if any)."
    ),
    bounds: Optional[str] = typer.Option(None, help=BOUNDS_HELP),
    gpkg: Optional[Path] = typer.Option(
        None,
        "--gpkg",
        help="Write this GeoPackage instead of the page, to review in a GIS: "
        "the review draft's boundaries to edit (layer boundaries), those held back from it "
        "(held_back) and an empty 'complete' polygon layer (apply-review reads it).",
    ),
    quiet: QuietOption = False,
) -> None:
    """A self-contained review page: imagery with pan and zoom, boundaries coloured by
    confidence, the least sure first (those not worth a look held back, hidden until asked
    for); accept, delete or cut a boundary, move a vertex, draw, delete the doubtful boundaries
    of an area, mark areas complete; edits exported as GeoJSON for apply-review. Open
    OUT/index.html (no network needed). With --bounds, one district of the city (its edits merge
    into the whole city all the same)."""
    from csboundary.pipeline.outputs.review import write_review, write_review_layers

    box = district_bounds(bounds)
    if gpkg is not None:
        from csboundary.data.atomic import check_output_file

        if (
            box is not None
        ):  # apply-review takes an edge missing from the layer as deleted: a district's layer would delete the rest
            raise typer.BadParameter(
                "--gpkg writes the whole city's edges; review a district with the page (--bounds without --gpkg)",
                param_hint="--gpkg",
            )

        done = write_review_layers(prediction, check_output_file(gpkg, (".gpkg",)))
        typer.echo(
            f"{done['gpkg']}: {done['boundaries']} boundaries to review ({done['edges']} edges; layers boundaries, "
            f"held_back ({done['held_back']} not worth a look), complete)"
        )
        return
    out_dir(out or prediction / "review")
    done = write_review(prediction, out, ground_truth, progress=not quiet, bounds=box)
    truth = f", ground truth {done['ground_truth']}" if done["ground_truth"] else ""
    typer.echo(
        f"{done['page']}: {done['draft']} boundaries to review ({done['edges']} edges; "
        f"{done['boundaries'] - done['draft']} held back){truth}"
    )


def apply_review(
    prediction: Path = typer.Argument(..., help="The predict output folder the review page was made from."),
    edits: Path = typer.Argument(
        ...,
        help="The edits the page exported (edits.geojson), or a copy of the prediction's "
        "boundaries.gpkg whose edges layer was edited in QGIS (with an optional 'complete' polygon layer).",
    ),
) -> None:
    """Merge a reviewer's edits into the prediction: rewrites graph.json, the GeoPackage, the
    GeoJSON and map.osm (when present), and appends what a person changed, and the areas marked
    complete (labels for csboundary finetune), to review.json."""
    from csboundary.pipeline.outputs.review_apply import apply_review as merge

    done = merge(prediction, edits)
    if "already_applied" in done:
        typer.echo(
            f"{prediction}: {edits} was already applied on {done['already_applied'].get('time', '?')}; nothing changed"
        )
        return
    typer.echo(
        f"{prediction}: {len(done['deleted_edges'])} deleted, {len(done['accepted_edges'])} accepted, "
        f"{len(done['moved_vertices'])} vertices moved, {len(done['added_edges'])} added, "
        f"{len(done['complete_areas'])} areas marked complete: "
        f"{done['edges_before']} -> {done['edges_after']} edges; recorded in {done['log']}"
    )


def qgis_plugin(
    out: Path = typer.Option(Path("csboundary_qgis.zip"), "--out", help="The plugin's zip to write."),
) -> None:
    """Write the QGIS plugin's zip (QGIS 3.22 or later: Plugins > Manage and Install Plugins >
    Install from ZIP): csboundary's commands in the Processing Toolbox, predictions loaded as
    styled layers, review with QGIS's editing tools (docs/qgis.md)."""
    from csboundary.data.atomic import check_output_file
    from csboundary.qgis_plugin import plugin_version, write_plugin_zip

    written = write_plugin_zip(check_output_file(out, (".zip",)))
    here = [
        p
        for p in (Path(sys.argv[0]), Path(sys.executable).with_name("csboundary"))
        if p.name.startswith("csboundary") and p.is_file()
    ]
    typer.echo(
        f"{written}: the csboundary QGIS plugin {plugin_version()}; give it this environment's command under Settings > "
        f"Options > Processing > Providers > csboundary: {here[0].resolve() if here else 'csboundary'}"
    )


def demo(
    out: Path = typer.Option(Path("out/demo"), help="Output directory."),
    seed: int = typer.Option(0, min=0, help="City seed (test split)."),
    engine: EngineOption = "auto",
    precision: PrecisionOption = "auto",
    device: DeviceOption = "auto",
) -> None:
    """The main job on an embedded default: a small test-split city, predicted and scored.

    Synthesizes a 3000x3000 px city (2x2 tiles, 3x3 patches) into OUT/city, predicts it with the
    shipped weights exactly as `csboundary predict` does (outputs in OUT/prediction), scores it
    against the ground truth at patch and city scale (OUT/scores.json) and prints the table.
    """
    from csboundary.metrics.report import format_rows
    from csboundary.pipeline.jobs.demo import run_demo
    from csboundary.pipeline.outputs.run_summary import stage_table
    from csboundary.pipeline.prediction.patch import load_predictor

    out_dir(out)
    done = run_demo(out, load_predictor(None, device, engine=engine, precision=precision), seed)
    meta, (width, height) = done["meta"], done["size"]
    typer.echo(format_rows(done["scores"]))
    typer.echo(
        f"demo city (test split, seed {seed}): {width}x{height} px, {len(meta['tiles'])} tiles, "
        f"{meta['counts']['boundaries']} boundaries ({meta['counts']['boundary_km']} km)\n{stage_table(done['summary'])}\n"
        f"wrote {out / 'prediction'} (boundaries.gpkg, boundaries.geojson, graph.json, overview.png, detail.png, summary.json), "
        f"{out / 'scores.json'}, {out / 'city'}"
    )
