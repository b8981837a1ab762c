"""Command-line entry point. Each command is a thin shell over a library function.

Input problems surface as ``error: <file>: <problem>`` on one line with exit status 2;
documented fallbacks (no CRS, 3-band RGB) as ``warning: ...`` lines.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import warnings
from pathlib import Path
from typing import Optional

import typer

from csboundary.cli.options import finite
from csboundary.errors import InputError, InputWarning

app = typer.Typer(add_completion=False, no_args_is_help=True, help="City-scale road-boundary graphs from aerial imagery.")
SUPPORT_HELP = "Mean boundary probability an AfANet edge needs along its length (0 = no check; default: the weights')."
LENGTH_HELP = "Longest AfANet edge kept, in pixels (0 = no limit; default: the weights')."


def _parse_tiles(text: str) -> tuple[int, int]:
    try:
        rows, cols = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise typer.BadParameter(f"expected ROWSxCOLS such as 2x2, got {text!r}")
    if rows < 1 or cols < 1:
        raise typer.BadParameter(f"tiles must be at least 1x1, got {text!r}")
    return rows, cols


@app.command()
def synth(
    out: Path = typer.Argument(..., help="Output city directory (tiles/, ground_truth.gpkg, city.json)."),
    seed: int = typer.Option(0, min=0, help="City seed; the split is mixed in, so splits never share a city."),
    tiles: str = typer.Option("1x1", help="Tile grid as ROWSxCOLS."),
    tile_size: int = typer.Option(5000, min=64, help="Tile side in pixels."),
    gsd: float = typer.Option(0.152, callback=finite, min=0.01, help="Ground sampling distance, metres per pixel."),
    split: str = typer.Option("train", help="train | valid | test."),
    style: str = typer.Option("classic", help="City style: classic, grid, downtown, suburb, rural, irregular, or mix (one drawn from the seed); see docs/styles.md."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Synthesize an aerial city with exact vector road-boundary ground truth."""
    from csboundary.data.synth.city import synthesize_city
    from csboundary.data.synth.config import SPLITS
    from csboundary.data.synth.styles import MIX, STYLES, draw_style, style_config

    if split not in SPLITS:
        raise typer.BadParameter(f"split must be one of {', '.join(SPLITS)}", param_hint="--split")
    if style != MIX and style not in STYLES:
        raise typer.BadParameter(f"unknown style {style!r}; choose one of {', '.join(STYLES)} or {MIX}", param_hint="--style")
    if style == MIX:
        style = draw_style(split, seed)
    _no_file_at(out)
    meta = synthesize_city(out, seed, split, _parse_tiles(tiles), style_config(style, tile_size=tile_size, gsd=gsd), progress=not quiet)
    counts = meta["counts"]
    typer.echo(
        f"{out}: {style} city, {len(meta['tiles'])} tile(s) of {tile_size}x{tile_size} px, {counts['boundaries']} boundaries "
        f"({counts['boundary_km']} km), render {max(meta['seconds']['render_per_tile']):.1f} s/tile"
    )


@app.command("import-topo-boundary")
def import_topo_boundary_cmd(
    root: Path = typer.Argument(..., help="Folder holding the Topo-boundary TTTTTT_RC.tiff patches, labels/dense_seq and data_split.json."),
    out: Path = typer.Option(..., "--out", help="Output folder: one city directory per 6-digit tile id."),
    patch_size: int = typer.Option(1000, min=1, help="Patch side in pixels (the benchmark's is 1000)."),
    splits: int = typer.Option(5, min=1, help="Patches per tile side (the benchmark's is 5)."),
    placement: bool = typer.Option(True, "--placement/--no-placement", help="Place tiles without georeference on the map from their 6-digit ids (an inference, docs/city-inference.md) and write one city per split."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Reassemble Topo-boundary patches into 5000x5000 tiles with vector ground truth, and the
    tiles of each split into one georeferenced city (city-<split>/) for city-scale evaluation."""
    from csboundary.data.topo_boundary import import_topo_boundary

    _out_dir(out)
    report = import_topo_boundary(root, out, patch_size=patch_size, splits=splits, progress=not quiet, placement=placement)
    for split, city in report["split_cities"].items():
        share = city["border_continuity"]["share"]
        typer.echo(f"{city['city_dir']}: {city['tiles']} tile(s) of split {split}, {city['boundaries']} boundaries"
                   + (f"; {share:.0%} of boundary ends at shared tile edges continue" if share is not None else ""))
    missing = report["missing_patches"]
    typer.echo(f"{out}: {len(report['tiles_written'])} tile(s) written; {len(missing)} missing patch(es)"
               + (f": {', '.join(missing[:10])}{' ...' if len(missing) > 10 else ''}" if missing else ""))


@app.command("import-masks")
def import_masks_cmd(
    source: Path = typer.Argument(..., help="Folder of images and their label masks."),
    out: Path = typer.Option(..., "--out", help="Folder for one city per image, plus set.json listing them."),
    gsd: Optional[float] = typer.Option(None, callback=finite, help="Pixel size of the images in metres (needed when they carry no georeference)."),
    target_gsd: float = typer.Option(0.152, callback=finite, help="Pixel size to resample to (the shipped model's: 0.152 m)."),
    image_pattern: str = typer.Option("{id}_image.png", help="Image file names; {id} is the part shared with the mask."),
    mask_pattern: str = typer.Option("{id}_edge.png", help="Mask file names."),
    kind: str = typer.Option("edge", help="edge: the mask marks road-edge lines | surface: it marks the road surface."),
    channel: int = typer.Option(1, min=1, help="Band of the mask file to read (1-based)."),
    threshold: float = typer.Option(128, callback=finite, help="Mask pixels above this value are labelled."),
    invert: bool = typer.Option(False, "--invert", help="Label pixels below the threshold instead (dark lines on white)."),
    ids: Optional[str] = typer.Option(None, help="Comma-separated ids to import (default: every pair found)."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Images + raster masks (road edge or road surface) -> cities with vector ground truth at the
    model's pixel size, for evaluate-set, evaluate-model and training."""

    from csboundary.labels.mask_import import MaskRule, import_masks

    if gsd is not None and (not math.isfinite(gsd) or gsd <= 0):
        raise typer.BadParameter(f"--gsd must be a positive number of metres, got {gsd}")
    if not math.isfinite(target_gsd) or target_gsd <= 0:
        raise typer.BadParameter(f"--target-gsd must be a positive number of metres, got {target_gsd}")
    try:
        rule = MaskRule(kind=kind, channel=channel - 1, threshold=threshold, invert=invert)
    except ValueError as exc:
        raise typer.BadParameter(str(exc))
    _out_dir(out)
    report = import_masks(source, out, gsd=gsd, rule=rule, image_pattern=image_pattern, mask_pattern=mask_pattern,
                          target_gsd=target_gsd, ids=ids.split(",") if ids else None, progress=not quiet)
    total = sum(c["boundaries"] for c in report["cities"])
    typer.echo(f"{out}: {len(report['cities'])} cities, {total} boundary lines, at {target_gsd:g} m/px (set.json lists them)")


@app.command("make-city")
def make_city_cmd(
    tiles: list[Path] = typer.Argument(..., help="GeoTIFF tile(s) or a folder of them (one pixel grid, one CRS)."),
    ground_truth: Path = typer.Option(..., "--ground-truth", help="Road boundaries as lines (GeoPackage, GeoJSON, Shapefile...) with a CRS."),
    out: Path = typer.Option(..., "--out", help="City directory to write (tiles are linked, not copied)."),
) -> None:
    """Your own GeoTIFFs + vector road boundaries -> a city directory, for evaluate-model,
    evaluate-set, benchmark --city and training (extra_train_cities)."""
    from csboundary.data.user_city import make_city

    _no_file_at(out)
    meta = make_city(tiles, ground_truth, out)
    typer.echo(f"{out}: {len(meta['tiles'])} tile(s), {meta['width']}x{meta['height']} px at {meta['gsd']:g} m, {meta['boundaries']} boundaries")


@app.command("evaluate-set")
def evaluate_set_cmd(
    set_dir: Path = typer.Argument(..., help="A folder of labelled cities (import-masks output, or city directories)."),
    weights: Optional[Path] = typer.Option(None, help="Weights bundle (default: the shipped weights)."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write per-city and mean scores as JSON here."),
    seed: int = typer.Option(0, help="Seed of the APLS/TLTS pair sampling."),
    edge_threshold: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help="Adjacency probability for an edge (default: the weights')."),
    min_edge_support: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help=SUPPORT_HELP),
    max_edge_length: Optional[float] = typer.Option(None, callback=finite, min=0.0, help=LENGTH_HELP),
    engine: str = typer.Option("auto", help="auto | torch | onnx: the networks on PyTorch or ONNX Runtime (auto: onnx on a CPU when installed)."),
    device: str = typer.Option("auto", help="auto | cpu | cuda."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Score a model on every city of a validation set (city scale) and print the per-city and
    mean scores: how to select and compare models on real labelled imagery."""
    from csboundary.cli.evaluate import write_scores
    from csboundary.pipeline.evaluate_set import evaluate_set, format_set

    if json_out is not None:
        _out_file(json_out, (".json",))
    predictor = _load_predictor(weights, device, edge_threshold, min_edge_support, max_edge_length, engine=engine)
    result = evaluate_set(set_dir, predictor, seed=seed, progress=not quiet)
    result["weights"] = str(weights or "shipped")
    typer.echo(format_set(result))
    if json_out is not None:
        write_scores(json_out, result)


def _parse_floats(text: str, count: int, option: str, form: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise typer.BadParameter(f"expected {form}, got {text!r}", param_hint=option)
    return values


def _parse_ints(text: str, count: int, option: str, form: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count:
        raise typer.BadParameter(f"expected {form}, got {text!r}", param_hint=option)
    return values


def _open_inputs(inputs: list[Path], ground_truth: Optional[Path]):
    """A city directory gives its tiles and ground truth; otherwise rasters and an optional GT file."""
    from csboundary.data import city as layout
    from csboundary.data.ground_truth import read_ground_truth
    from csboundary.data.raster import Mosaic

    looks_like_city = len(inputs) == 1 and (layout.tiles_dir(inputs[0]).is_dir() or layout.ground_truth_path(inputs[0]).exists())
    if looks_like_city:
        layout.read_meta(inputs[0])  # a city without a readable city.json is an interrupted write, not input
    if len(inputs) == 1 and layout.is_city_dir(inputs[0]):
        mosaic = Mosaic.open(layout.tiles_dir(inputs[0]))
        if ground_truth is None and layout.ground_truth_path(inputs[0]).exists():
            ground_truth = layout.ground_truth_path(inputs[0])
    else:
        mosaic = Mosaic.open(inputs)
    lines = []
    if ground_truth is not None:
        lines = list(read_ground_truth(ground_truth, mosaic.crs).geometry)
    return mosaic, lines


@app.command()
def show(
    inputs: list[Path] = typer.Argument(..., help="A city directory, GeoTIFF tile(s), or a directory of tiles."),
    out: Path = typer.Option(..., "--out", help="PNG to write."),
    window: Optional[str] = typer.Option(None, help="Pixel window COL,ROW,WIDTH,HEIGHT in mosaic pixels."),
    bounds: Optional[str] = typer.Option(None, help="World window MINX,MINY,MAXX,MAXY in the mosaic's CRS."),
    ground_truth: Optional[Path] = typer.Option(None, help="Boundaries to draw (GeoPackage/GeoJSON); a city's own by default."),
    max_size: int = typer.Option(2000, min=16, help="Downsample so the longest side is at most this many pixels."),
    grid: bool = typer.Option(False, help="Draw the patch grid (cores red, 1100 px expanded windows yellow)."),
    labels: Optional[Path] = typer.Option(None, help="A folder from `csboundary labels`: draw one patch's labels (needs --patch)."),
    patch: Optional[str] = typer.Option(None, help="Patch ROW,COL of the grid: the window becomes its 1100x1100 expanded window."),
) -> None:
    """Draw a window of the imagery with road boundaries (or a patch's labels) over it."""
    import json

    from csboundary.data.grid import GridConfig, PatchGrid
    from csboundary.data.windows import PixelWindow
    from csboundary.viz.overlay import render_window, write_png

    if sum(x is not None for x in (window, bounds, patch)) > 1:
        raise typer.BadParameter("give one of --window, --bounds, --patch")
    if labels is not None and patch is None:
        raise typer.BadParameter("--labels needs --patch ROW,COL")
    _out_file(out, (".png",))
    mosaic, lines = _open_inputs(inputs, ground_truth)
    if patch is not None:
        grid_config = GridConfig()
        if labels is not None:
            from csboundary.labels.writer import MANIFEST

            manifest = labels / MANIFEST
            if not manifest.exists():
                raise InputError(labels, f"not a labels folder (no {MANIFEST})")
            grid_config = GridConfig(**json.loads(manifest.read_text())["config"]["grid"])
        row, col = _parse_ints(patch, 2, "--patch", "ROW,COL")
        grid_ = PatchGrid(mosaic.width, mosaic.height, mosaic.transform, grid_config)
        if (row, col) not in grid_:
            raise typer.BadParameter(f"patch {row},{col} is outside the {grid_.n_rows}x{grid_.n_cols} grid", param_hint="--patch")
        the_patch = grid_.patch(row, col)
        window = ",".join(str(v) for v in (the_patch.expanded.col_off, the_patch.expanded.row_off, the_patch.expanded.width, the_patch.expanded.height))
        if labels is not None:
            from csboundary.graph import BoundaryGraph
            from csboundary.labels.writer import PATCH_DIR, load_patch_arrays, patch_stem
            from csboundary.viz.labels import draw_patch_labels
            from csboundary.viz.overlay import to_display

            stem = patch_stem(the_patch)
            arrays = load_patch_arrays(labels / PATCH_DIR / f"{stem}.npz")
            graph = BoundaryGraph.read_json(labels / PATCH_DIR / f"{stem}.graph.json")
            with mosaic:
                read = mosaic.read(the_patch.expanded)
            core = the_patch.core_local
            rgb = draw_patch_labels(to_display(read.data, read.valid), arrays, graph, (core.col_off, core.row_off, core.col_end, core.row_end))
            write_png(out, rgb)
            typer.echo(f"{out}: labels of patch {row},{col}: {graph.n_vertices} vertices, {graph.n_edges} edges")
            return
    with mosaic:
        if window:
            c, r, w, h = _parse_ints(window, 4, "--window", "COL,ROW,WIDTH,HEIGHT")
            if w <= 0 or h <= 0:
                raise typer.BadParameter("width and height must be positive", param_hint="--window")
            win = PixelWindow(c, r, w, h)
        elif bounds:
            win = mosaic.window_from_bounds(*_parse_floats(bounds, 4, "--bounds", "MINX,MINY,MAXX,MAXY"))
        else:
            win = mosaic.window
        inside = win.intersection(mosaic.window)
        if inside is None or inside.is_empty:
            where = f" in {mosaic.crs.to_string()} coordinates" if bounds and mosaic.crs is not None else ""
            raise InputError(inputs[0], f"the window{where} lies outside the imagery ({mosaic.width}x{mosaic.height} px, bounds {tuple(round(b, 3) for b in mosaic.bounds)})")
        win = inside  # nothing to draw beyond the imagery; memory stays bounded by it
        if lines and not _any_line_in(lines, mosaic, win):
            warnings.warn(f"{ground_truth or inputs[0]}: none of the {len(lines)} boundaries lies in the window (wrong CRS, or a file without one?)",
                          InputWarning, stacklevel=1)
        rgb = render_window(mosaic, win, lines, max_size=max_size, grid=PatchGrid.for_mosaic(mosaic) if grid else None)
    write_png(out, rgb)
    typer.echo(f"{out}: {win.width}x{win.height} px window, {len(lines)} boundaries")


def _any_line_in(lines, mosaic, window) -> bool:
    import shapely

    x0, y1 = mosaic.pixel_to_world(window.col_off, window.row_off)
    x1, y0 = mosaic.pixel_to_world(window.col_end, window.row_end)
    box = shapely.box(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))
    return any(line.intersects(box) for line in lines)


@app.command()
def labels(
    city: Path = typer.Argument(..., help="A city directory (from `csboundary synth` or `import-topo-boundary`)."),
    out: Path = typer.Option(..., "--out", help="Output folder for per-patch labels."),
    core: int = typer.Option(1000, min=16, help="Patch core size, px (paper: 1000)."),
    margin: int = typer.Option(50, min=0, help="Patch margin on every side, px (paper: 50)."),
    aux_spacing: int = typer.Option(250, min=0, help="Auxiliary keypoint grid spacing, px (0 = none)."),
    segmentation_width: int = typer.Option(3, min=1, help="Boundary width in the segmentation label, px."),
    heat_sigma: float = typer.Option(3.0, callback=finite, min=0.1, help="Gaussian sigma of the keypoint map, px."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Write every patch's training labels: segmentation, orientation, keypoint map, graph."""
    from csboundary.data.grid import GridConfig
    from csboundary.labels.config import LabelConfig
    from csboundary.labels.writer import write_city_labels

    config = LabelConfig(grid=GridConfig(core, margin), aux_spacing_px=aux_spacing, segmentation_width=segmentation_width, heat_sigma_px=heat_sigma)
    _out_dir(out)
    manifest = write_city_labels(city, out, config, progress=not quiet)
    c = manifest["counts"]
    typer.echo(f"{out}: {c['patches']} patches, {c['vertices']} vertices, {c['edges']} edges ({c['corner_edges']} corner) in {manifest['seconds']['total']:.1f} s")


@app.command()
def train(
    model: str = typer.Argument(..., help="fpn | afanet | a baseline: orientation-refine | sat2graph | icurb."),
    config: Path = typer.Option(..., "--config", help="Training config JSON (see configs/)."),
    out: Path = typer.Option(..., "--out", help="Run folder: checkpoints, train.log."),
    resume: Optional[Path] = typer.Option(None, help="Checkpoint (*-last.pt) to resume from."),
    steps: Optional[int] = typer.Option(None, min=1, help="Override the config's step count."),
    fpn_weights: Optional[Path] = typer.Option(None, help="AfANet only: the trained FPN (overrides the config)."),
    device: str = typer.Option("auto", help="auto | cpu | cuda."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Train the FPN, AfANet or a baseline on synthetic cities (built on first use under the config's cache)."""
    import json as _json

    from csboundary.models.device import resolve_device
    from csboundary.models.baselines import METHODS, baseline_module
    from csboundary.models.training.afanet import train_afanet
    from csboundary.models.training.config import TrainConfig
    from csboundary.models.training.fpn import train_fpn

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
    _out_dir(out)
    from csboundary.data.atomic import atomic_path

    with atomic_path(out / "config.json") as tmp:
        tmp.write_text(_json.dumps(cfg.to_dict(), indent=2) + "\n")
    runner = {"fpn": train_fpn, "afanet": train_afanet}.get(model) or baseline_module(model).train
    weights = runner(cfg, out, resolved, str(resume) if resume else None, progress=not quiet)
    typer.echo(f"{weights}: trained {model} ({cfg.steps} steps); log in {out / 'train.log'}")


@app.command("bundle-weights")
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

    _out_file(out, (".pt",))
    path = make_bundle(fpn, afanet, out, edge_threshold, min_support=min_edge_support, max_length_px=max_edge_length,
                       crossing_spacing_px=grid_crossings)
    typer.echo(f"{path}: {path.stat().st_size / 1e6:.1f} MB")


@app.command("evaluate-model")
def evaluate_model(
    city: Path = typer.Argument(..., help="A city directory with ground truth (e.g. a valid-split synthetic city)."),
    weights: Optional[Path] = typer.Option(None, help="Weights bundle (default: the shipped weights)."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the results as JSON here."),
    seed: int = typer.Option(0, help="Seed of the APLS/TLTS pair sampling."),
    edge_threshold: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help="Adjacency probability for an edge (default: the weights')."),
    min_edge_support: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help=SUPPORT_HELP),
    max_edge_length: Optional[float] = typer.Option(None, callback=finite, min=0.0, help=LENGTH_HELP),
    batch_size: int = typer.Option(1, min=1, help="Patches per FPN batch."),
    engine: str = typer.Option("auto", help="auto | torch | onnx: the networks on PyTorch or ONNX Runtime (auto: onnx on a CPU when installed)."),
    device: str = typer.Option("auto", help="auto | cpu | cuda."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """Evaluate a model on a city at patch scale (each patch's graph on its core) and city scale
    (the stitched graph), without writing the prediction."""
    from csboundary.cli.evaluate import format_rows, write_scores
    from csboundary.data import city as layout
    from csboundary.pipeline.city import predict_city
    from csboundary.pipeline.run import evaluate_run

    if json_out is not None:
        _out_file(json_out, (".json",))
    from csboundary.data.model_view import model_view

    layout.read_meta(city)
    mosaic, lines = _open_inputs([city], None)
    predictor = _load_predictor(weights, device, edge_threshold, min_edge_support, max_edge_length, engine=engine)
    view = model_view(mosaic, model_gsd=predictor.pixel_size_m)
    with view.mosaic:
        result = predict_city(view.mosaic, predictor, batch_size=batch_size, progress=not quiet)
    scores = evaluate_run(result, lines, seed)
    for item in scores.values():
        item["inputs"] = {"pred": f"{weights or 'shipped weights'} on {city}", "gt": str(layout.ground_truth_path(city))}
    typer.echo(format_rows(scores))
    if json_out is not None:
        write_scores(json_out, scores)


def _load_predictor(weights: Optional[Path], device: str, edge_threshold: Optional[float] = None,
                    min_edge_support: Optional[float] = None, max_edge_length: Optional[float] = None, fpn_weights: Optional[Path] = None,
                    engine: str = "auto"):
    """The predictor of a weights bundle, with the command line's overrides of its inference
    settings, on the chosen engine (``auto``: ONNX Runtime on a CPU when installed)."""
    import dataclasses

    from csboundary.models.device import resolve_device
    from csboundary.pipeline.patch import PatchPredictor

    predictor = PatchPredictor.load(weights, resolve_device(device), fpn_weights)
    if edge_threshold is not None:
        predictor.edge_threshold = edge_threshold
    if min_edge_support is not None:
        predictor.support = dataclasses.replace(predictor.support, min_support=min_edge_support)
    if max_edge_length is not None:
        predictor.support = dataclasses.replace(predictor.support, max_length_px=max_edge_length)
    predictor.use_engine(engine, weights, fpn_weights)
    return predictor



@app.command()
def predict(
    inputs: list[Path] = typer.Argument(..., help="GeoTIFF tile(s), a directory of tiles, or a city directory."),
    out: Path = typer.Option(..., "--out", help="Output folder (boundaries.gpkg/.geojson, graph.json, PNGs, summary.json)."),
    weights: Optional[Path] = typer.Option(None, help="Weights bundle (default: the shipped weights)."),
    edge_threshold: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help="Adjacency probability for an edge (default: the weights')."),
    min_edge_support: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help=SUPPORT_HELP),
    max_edge_length: Optional[float] = typer.Option(None, callback=finite, min=0.0, help=LENGTH_HELP),
    batch_size: int = typer.Option(1, min=1, help="Patches per FPN batch (more is faster on a GPU, needs more memory)."),
    write_maps: bool = typer.Option(False, "--write-maps", help="Also write the stitched probability maps as a Cloud-Optimized GeoTIFF (maps.tif)."),
    lanelet2: bool = typer.Option(False, "--lanelet2", help="Also write the boundaries as a Lanelet2 map (map.osm + map_projector_info.yaml)."),
    gsd: Optional[float] = typer.Option(None, callback=finite, min=0.0, help="Pixel size in metres of imagery without a CRS (needed then)."),
    restart: bool = typer.Option(False, "--restart", help="Discard the unfinished run in --out instead of resuming it."),
    scheduler: Optional[str] = typer.Option(None, help="Run on this Dask cluster (tcp://HOST:8786); --out must be on a filesystem its workers share."),
    workers: Optional[int] = typer.Option(None, min=1, help="Run on a local Dask cluster of this many worker processes."),
    threads: Optional[int] = typer.Option(None, min=1, help="Torch threads per process (default: all cores; with --workers N, cores / N)."),
    engine: str = typer.Option("auto", help="auto | torch | onnx: the networks on PyTorch or ONNX Runtime (auto: onnx on a CPU when installed)."),
    device: str = typer.Option("auto", help="auto | cpu | cuda."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """City-scale prediction: patch grid -> FPN -> averaged maps -> vertices -> AfANet -> stitched
    city graph, written in the input's CRS. Any pixel size from 0.03 to 1 m, any CRS (metres,
    feet, degrees) and 8/16-bit or float imagery are resampled and stretched on the fly
    (docs/city-inference.md). Work is kept as it is done: the same command after an interruption
    continues where it stopped (docs/scaling.md)."""
    import contextlib

    from csboundary.data.model_view import model_view
    from csboundary.models.checkpoint import file_sha256
    from csboundary.models.checkpoint import shipped_weights
    from csboundary.pipeline.run import run_prediction, stage_table

    mosaic, _ = _open_inputs(inputs, None)
    predictor = _load_predictor(weights, device, edge_threshold, min_edge_support, max_edge_length, engine=engine)
    view = model_view(mosaic, gsd, predictor.pixel_size_m)
    _out_dir(out, inputs)
    from csboundary.data.grid import PatchGrid

    plan = PatchGrid.for_mosaic(view.mosaic)
    typer.echo(f"{out}: {len(plan)} patches ({plan.n_rows}x{plan.n_cols}) over {view.mosaic.width}x{view.mosaic.height} px "
               f"at {predictor.pixel_size_m:g} m", err=True)
    if scheduler and workers:
        raise typer.BadParameter("give --scheduler or --workers, not both")
    if threads and not (scheduler or workers):
        import torch

        torch.set_num_threads(threads)
    settings = {"weights": str(weights or "shipped"), "weights_sha256": file_sha256(weights or shipped_weights()),
                "edge_threshold": predictor.edge_threshold, "support": [predictor.support.min_support, predictor.support.max_length_px],
                "batch_size": batch_size, "device": str(predictor.device), "engine": predictor.engine, "input_pixel_m": [round(v, 5) for v in view.source_pixel_m],
                "resampled": view.resampled, "stretch": None if view.stretch is None else {"low": view.stretch.low, "high": view.stretch.high}}
    with view.mosaic, contextlib.ExitStack() as stack:
        options = {}
        if scheduler or workers:
            from csboundary.pipeline.distributed import dask_client, dask_executor

            client, worker_threads = stack.enter_context(dask_client(scheduler, workers))
            options = {"executor": dask_executor(client), "threads": threads or worker_threads}
            settings["cluster"] = scheduler or f"local, {workers} workers"  # not part of the run's manifest: a run may resume elsewhere
        _, summary = run_prediction(view.mosaic, predictor, out, write_maps=write_maps, batch_size=batch_size, progress=not quiet,
                                    settings=settings, units=view.units, restart=restart, lanelet2=lanelet2, **options)
    c = summary["counts"]
    typer.echo(f"{out}: {c['edges']} edges, {c['vertices']} vertices, {c['boundary_km']} km of boundary\n{stage_table(summary)}")


@app.command("export-lanelet2")
def export_lanelet2(
    prediction: Path = typer.Argument(..., help="A predict output folder (its graph.json), or a graph.json file."),
    out: Path = typer.Option(..., "--out", help="Lanelet2 OSM file to write; map_projector_info.yaml goes beside it."),
    origin: Optional[str] = typer.Option(None, help="Projection origin LAT,LON (default: the middle of the boundaries)."),
) -> None:
    """The predicted boundaries as a Lanelet2 map: one road_border linestring per boundary (closed
    loops closed), confidence as an attribute, UTM projector around the origin (Autoware's
    map_projector_info.yaml beside it)."""
    from csboundary.graph import BoundaryGraph
    from csboundary.pipeline.lanelet2_export import write_lanelet2

    source = prediction / "graph.json" if prediction.is_dir() else prediction
    _out_file(out, (".osm",))
    at = None
    if origin is not None:
        lat, lon = (float(v) for v in _parse_floats(origin, 2, "--origin", "LAT,LON"))
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            raise typer.BadParameter(f"{origin!r} is not a latitude,longitude", param_hint="--origin")
        at = (lat, lon)
    written = write_lanelet2(BoundaryGraph.read_json(source), out, at)
    typer.echo(f"{out}: {written['linestrings']} road_border linestrings; origin {written['origin'][0]:.7f},{written['origin'][1]:.7f} "
               f"in {written['projector_info']}")


@app.command()
def review(
    prediction: Path = typer.Argument(..., help="A predict output folder."),
    out: Optional[Path] = typer.Option(None, "--out", help="Folder of the page (default: PREDICTION/review)."),
    ground_truth: Optional[Path] = typer.Option(None, help="Boundaries to show as a toggle (default: the city's own, if any)."),
    quiet: bool = typer.Option(False, help="No progress bar."),
) -> None:
    """A self-contained review page: imagery with pan and zoom, boundaries coloured by
    confidence, the least sure first; accept, delete, move and draw, edits exported as GeoJSON
    for apply-review. Open OUT/index.html (no network needed)."""
    from csboundary.pipeline.review import write_review

    _out_dir(out or prediction / "review")
    done = write_review(prediction, out, ground_truth, progress=not quiet)
    typer.echo(f"{done['page']}: {done['edges']} edges to review{', ground truth ' + str(done['ground_truth']) if done['ground_truth'] else ''}")


@app.command("apply-review")
def apply_review(
    prediction: Path = typer.Argument(..., help="The predict output folder the review page was made from."),
    edits: Path = typer.Argument(..., help="The edits the page exported (edits.geojson)."),
) -> None:
    """Merge a reviewer's edits into the prediction: rewrites graph.json, the GeoPackage, the
    GeoJSON and map.osm (when present), and appends what a person changed to review.json."""
    from csboundary.pipeline.review import apply_review as merge

    done = merge(prediction, edits)
    typer.echo(f"{prediction}: {len(done['deleted_edges'])} deleted, {len(done['accepted_edges'])} accepted, "
               f"{len(done['moved_vertices'])} vertices moved, {len(done['added_edges'])} added: "
               f"{done['edges_before']} -> {done['edges_after']} edges; recorded in {done['log']}")


@app.command("predict-patch")
def predict_patch(
    image: Path = typer.Argument(..., help="One patch: a GeoTIFF (or any raster) of at most 1100x1100 px, 4 bands (or RGB)."),
    out: Path = typer.Option(..., "--out", help="Output folder: graph.json, boundaries.geojson, overlay.png."),
    weights: Optional[Path] = typer.Option(None, help="Weights bundle (default: the shipped weights) or an AfANet checkpoint."),
    fpn_weights: Optional[Path] = typer.Option(None, help="FPN checkpoint, when --weights is an AfANet checkpoint."),
    edge_threshold: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help="Adjacency probability for an edge (default: the weights')."),
    min_edge_support: Optional[float] = typer.Option(None, callback=finite, min=0.0, max=1.0, help=SUPPORT_HELP),
    max_edge_length: Optional[float] = typer.Option(None, callback=finite, min=0.0, help=LENGTH_HELP),
    max_degree: Optional[int] = typer.Option(None, min=0, help="Edges per vertex at most (0 = no limit; default: the weights', 2 = polylines)."),
    gsd: Optional[float] = typer.Option(None, callback=finite, min=0.0, help="Pixel size in metres of an image without a CRS."),
    engine: str = typer.Option("auto", help="auto | torch | onnx: the networks on PyTorch or ONNX Runtime (auto: onnx on a CPU when installed)."),
    device: str = typer.Option("auto", help="auto | cpu | cuda."),
) -> None:
    """Predict the road-boundary graph of one patch (FPN -> vertices -> AfANet)."""
    import geopandas as gpd

    from csboundary.data.atomic import check_output_dir, staging_folder
    from csboundary.data.raster import Mosaic
    from csboundary.viz.labels import draw_patch_labels
    from csboundary.viz.overlay import to_display, write_png

    _out_dir(out, [image] if image.is_dir() else [])
    predictor = _load_predictor(weights, device, edge_threshold, min_edge_support, max_edge_length, fpn_weights, engine=engine)
    if max_degree is not None:
        predictor.max_degree = max_degree or None
    from csboundary.data.model_view import model_view

    with model_view(Mosaic.open(image), gsd, predictor.pixel_size_m, assume_model_gsd=True).mosaic as mosaic:
        if mosaic.width > 1100 or mosaic.height > 1100:
            raise InputError(image, f"is {mosaic.width}x{mosaic.height} px at the model's pixel size; predict-patch takes at most 1100x1100 (a patch)")
        read = mosaic.read(mosaic.window)
        maps = predictor.maps(read.data)
        graph = predictor.graph(read.data, maps)
        graph.transform, graph.crs = mosaic.transform, (mosaic.crs.to_string() if mosaic.crs else None)
    frame = gpd.GeoDataFrame(
        {"kind": graph.edge_kinds or [], "confidence": list(graph.edge_scores) if graph.edge_scores is not None else []},
        geometry=graph.to_linestrings(world=True), crs=graph.crs,
    )
    with staging_folder(check_output_dir(out, create=True), last="graph.json") as stage:
        graph.write_json(stage / "graph.json")
        frame.to_file(stage / "boundaries.geojson", driver="GeoJSON", engine="pyogrio", layer="boundaries")
        arrays = {"segmentation": maps[1] > 0.5, "keypoint_heat": maps[0]}
        write_png(stage / "overlay.png", draw_patch_labels(to_display(read.data, read.valid), arrays, graph))
    typer.echo(f"{out}: {graph.n_vertices} vertices, {graph.n_edges} edges ({sum(k == 'corner' for k in graph.edge_kinds or [])} corner)")


@app.command()
def benchmark(
    out: Path = typer.Option(Path("docs/benchmark"), help="Folder for tables.md, table*.csv, fig7-comparison.png, benchmark.json, predictions/."),
    city: Optional[Path] = typer.Option(None, help="Test city with ground truth (default: the test-split city seed 1, 1x1 tile of 5000 px, built on first use)."),
    weights_dir: Optional[Path] = typer.Option(None, help="Weights folder (default: the package's shipped weights)."),
    methods: Optional[str] = typer.Option(None, help="Comma-separated subset of: " + "csboundary, orientation-refine, sat2graph, icurb, ablation-full, no-global, no-local."),
    seed: int = typer.Option(0, help="Seed of the APLS/TLTS pair sampling."),
    device: str = typer.Option("auto", help="auto | cpu | cuda."),
    quiet: bool = typer.Option(False, help="No progress bars."),
) -> None:
    """The paper's comparison (Tables I-IV, Fig. 7): every method predicts one test city through the
    same pipeline and metrics; training times come from the logs beside the weights."""
    import json as _json

    from csboundary.data.atomic import atomic_path
    from csboundary.models.checkpoint import code_version
    from csboundary.models.device import resolve_device
    from csboundary.models.training.data import CitySpec
    from csboundary.pipeline.benchmark import METHODS, run_benchmark
    from csboundary.models.checkpoint import shipped_weights

    chosen = [m.strip() for m in methods.split(",")] if methods else None
    unknown = set(chosen or []) - {m.key for m in METHODS}
    if unknown:
        raise typer.BadParameter(f"unknown method(s) {', '.join(sorted(unknown))}", param_hint="--methods")
    _out_dir(out)
    city_dir = city or CitySpec("test", 1, (1, 1), 5000).ensure("data/cities")
    weights = weights_dir or shipped_weights().parent
    results = run_benchmark(Path(city_dir), out, Path(weights), resolve_device(device), chosen, seed, progress=not quiet)
    record = {"command": "csboundary " + " ".join(sys.argv[1:]), "code_version": code_version(), "city": str(city_dir), "weights": str(weights),
              "results": {k: {"method": r["method"].name, **({"missing": r["missing"]} if "missing" in r else
                              {"scores": {s: v["metrics"] for s, v in r["scores"].items()}, "training": r["training"],
                               "inference_seconds": r["summary"]["seconds"]})} for k, r in results.items()}}
    with atomic_path(out / "benchmark.json") as tmp:
        tmp.write_text(_json.dumps(record, indent=1, default=float) + "\n")
    typer.echo((out / "tables.md").read_text())


@app.command()
def demo(
    out: Path = typer.Option(Path("out/demo"), help="Output directory."),
    seed: int = typer.Option(0, min=0, help="City seed (test split)."),
    engine: str = typer.Option("auto", help="auto | torch | onnx: the networks on PyTorch or ONNX Runtime (auto: onnx on a CPU when installed)."),
    device: str = typer.Option("auto", help="auto | cpu | cuda."),
) -> None:
    """The main job on an embedded default: a small test-split city, predicted and scored.

    Synthesizes a 3000x3000 px city (2x2 tiles, 3x3 patches) into OUT/city, predicts it with the
    shipped weights exactly as `csboundary predict` does (outputs in OUT/prediction), scores it
    against the ground truth at patch and city scale (OUT/scores.json) and prints the table.
    """
    from csboundary.cli.evaluate import format_rows, write_scores
    from csboundary.data.synth.city import synthesize_city
    from csboundary.data.synth.config import SynthConfig
    from csboundary.pipeline.run import evaluate_run, run_prediction, stage_table

    _out_dir(out)
    predictor = _load_predictor(None, device, engine=engine)
    city_dir = out / "city"
    meta = synthesize_city(city_dir, seed, "test", (2, 2), SynthConfig(tile_size=1500))
    mosaic, lines = _open_inputs([city_dir], None)
    settings = {"weights": "shipped", "edge_threshold": predictor.edge_threshold, "device": str(predictor.device), "engine": predictor.engine}
    with mosaic:
        result, summary = run_prediction(mosaic, predictor, out / "prediction", settings=settings, ground_truth=lines)
    scores = evaluate_run(result, lines, seed=0)
    for item in scores.values():
        item["inputs"] = {"pred": str(out / "prediction"), "gt": str(city_dir / "ground_truth.gpkg")}
    write_scores(out / "scores.json", scores)
    typer.echo(format_rows(scores))
    typer.echo(
        f"demo city (test split, seed {seed}): {mosaic.width}x{mosaic.height} px, {len(meta['tiles'])} tiles, "
        f"{meta['counts']['boundaries']} boundaries ({meta['counts']['boundary_km']} km)\n{stage_table(summary)}\n"
        f"wrote {out / 'prediction'} (boundaries.gpkg, boundaries.geojson, graph.json, overview.png, detail.png, summary.json), "
        f"{out / 'scores.json'}, {city_dir}"
    )


def _out_dir(out: Path, inputs: list[Path] = ()) -> None:
    """The output folder is checked (and made) before any work; it must not lie inside an input
    folder, where the next run would read its maps.tif as imagery."""
    from csboundary.data.atomic import check_output_dir

    resolved = out.resolve()
    for item in inputs:
        if item.is_dir() and (resolved == item.resolve() or item.resolve() in resolved.parents):
            raise InputError(out, f"is inside the input folder {item}; its outputs would be read as imagery next time")
    check_output_dir(out)


def _out_file(path: Path, suffixes: tuple[str, ...]) -> None:
    from csboundary.data.atomic import check_output_file

    check_output_file(path, suffixes)


def _no_file_at(out: Path) -> None:
    """A folder-making command whose target is an existing file."""
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")


def _format_warning(message, category, filename, lineno, line=None) -> str:
    return f"warning: {message}\n"


class Interrupted(BaseException):
    """SIGINT or SIGTERM. A BaseException that is not KeyboardInterrupt, so that click does not
    turn Ctrl-C into its own exit before the temporaries are cleared and the user told."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _on_signal(signum, frame) -> None:
    raise Interrupted(signum)


def main() -> None:
    """Console entry point: run the app, turning input errors into one line and exit status 2,
    and Ctrl-C / SIGTERM into a message and exit 130 / 143 after every temporary is removed."""
    warnings.formatwarning = _format_warning
    warnings.simplefilter("always", InputWarning)
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    try:
        code = app(standalone_mode=False)
    except typer.Abort:
        typer.echo("aborted", err=True)
        sys.exit(1)
    except typer.TyperException as exc:  # click's usage errors (typer vendors click): one line too
        if type(exc).__name__ == "NoArgsIsHelpError":
            exc.show()
            sys.exit(2)
        ctx = getattr(exc, "ctx", None)
        where = f" (see csboundary {ctx.info_name} --help)" if ctx is not None and ctx.parent is not None else ""
        typer.echo(f"error: {' '.join(exc.format_message().split())}{where}", err=True)
        sys.exit(getattr(exc, "exit_code", 2))
    except InputError as exc:
        typer.echo(f"error: {exc}", err=True)
        sys.exit(2)
    except (OSError, MemoryError) as exc:  # a full disk, a vanished file, no memory: the system's problem, said in one line
        name = getattr(exc, "filename", None)
        typer.echo(f"error: {name + ': ' if name else ''}{exc.strerror or exc if isinstance(exc, OSError) else 'out of memory'}", err=True)
        sys.exit(1)
    except Exception as exc:  # a bug, not the user's input: one line, the traceback on request
        if os.environ.get("CSBOUNDARY_DEBUG"):
            raise
        message = " ".join(str(exc).split())[:300]
        typer.echo(f"error: internal error ({type(exc).__name__}: {message}); please report it, with the traceback "
                   "that CSBOUNDARY_DEBUG=1 prints", err=True)
        sys.exit(1)
    except (Interrupted, KeyboardInterrupt) as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        typer.echo(f"interrupted ({signal.Signals(signum).name}): temporaries removed; no partial file was left under a final name "
                   "(a predict run keeps its finished patches: the same command continues it)", err=True)
        sys.exit(128 + signum)
    sys.exit(code if isinstance(code, int) else 0)


from csboundary.cli.evaluate import evaluate  # noqa: E402
app.command()(evaluate)
