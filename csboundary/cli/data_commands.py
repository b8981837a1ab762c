"""Commands that make and look at inputs: synthetic cities, imported datasets, a user's own
tiles and labels, training labels, and pictures of any of them."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import typer

from csboundary.cli.options import (
    QuietOption,
    finite,
    no_file_at,
    out_dir,
    out_file,
    parse_numbers,
    parse_tiles,
    positive,
)
from csboundary.errors import InputError


def synth(
    out: Path = typer.Argument(..., help="Output city directory (tiles/, ground_truth.gpkg, city.json)."),
    seed: int = typer.Option(0, min=0, help="City seed; the split is mixed in, so splits never share a city."),
    tiles: str = typer.Option("1x1", help="Tile grid as ROWSxCOLS."),
    tile_size: int = typer.Option(5000, min=64, help="Tile side in pixels."),
    gsd: float = typer.Option(
        0.152,
        callback=finite,
        min=0.01,
        help="Ground sampling distance in metres per pixel on the ground, whatever --crs counts in.",
    ),
    crs: str = typer.Option(
        "EPSG:32618",
        help="CRS of the tiles and ground truth (default UTM 18N, metres); in any other (US feet, degrees) "
        "the city stays in the same place with the same pixels.",
    ),
    split: str = typer.Option("train", help="train | valid | test."),
    style: str = typer.Option(
        "classic",
        help="City style: classic, grid, downtown, suburb, rural, irregular, residential, leafy, or mix (one drawn "
        "from the seed); see docs/styles.md.",
    ),
    quiet: QuietOption = False,
) -> None:
    """Synthesize an aerial city with exact vector road-boundary ground truth."""
    from csboundary.data.synth.city import in_crs, synthesize_city
    from csboundary.data.synth.config import SPLITS
    from csboundary.data.synth.styles import MIX, STYLES, draw_style, style_config

    if split not in SPLITS:
        raise typer.BadParameter(f"split must be one of {', '.join(SPLITS)}", param_hint="--split")
    if style != MIX and style not in STYLES:
        raise typer.BadParameter(
            f"unknown style {style!r}; choose one of {', '.join(STYLES)} or {MIX}", param_hint="--style"
        )
    if style == MIX:
        style = draw_style(split, seed)
    config = style_config(style, tile_size=tile_size, gsd=gsd)
    if crs != config.crs:
        try:
            config = in_crs(config, crs)
        except ValueError as exc:
            raise InputError("--crs", str(exc)) from exc
    no_file_at(out)
    meta = synthesize_city(out, seed, split, parse_tiles(tiles), config, progress=not quiet)
    counts = meta["counts"]
    typer.echo(
        f"{out}: {style} city, {len(meta['tiles'])} tile(s) of {tile_size}x{tile_size} px, {counts['boundaries']} boundaries "
        f"({counts['boundary_km']} km), render {max(meta['seconds']['render_per_tile']):.1f} s/tile"
    )


def import_topo_boundary_cmd(
    root: Path = typer.Argument(
        ..., help="Folder holding the Topo-boundary TTTTTT_RC.tiff patches, labels/dense_seq and data_split.json."
    ),
    out: Path = typer.Option(..., "--out", help="Output folder: one city directory per 6-digit tile id."),
    patch_size: int = typer.Option(1000, min=1, help="Patch side in pixels (the benchmark's is 1000)."),
    splits: int = typer.Option(5, min=1, help="Patches per tile side (the benchmark's is 5)."),
    placement: bool = typer.Option(
        True,
        "--placement/--no-placement",
        help="Place tiles without georeference on the map from their 6-digit ids (an inference, "
        "docs/city-inference.md) and write one city per split.",
    ),
    quiet: QuietOption = False,
) -> None:
    """Reassemble Topo-boundary patches into 5000x5000 tiles with vector ground truth, and the
    tiles of each split into one georeferenced city (city-<split>/) for city-scale evaluation."""
    from csboundary.data.topo_boundary import import_topo_boundary

    out_dir(out)
    report = import_topo_boundary(
        root, out, patch_size=patch_size, splits=splits, progress=not quiet, placement=placement
    )
    for split, city in report["split_cities"].items():
        share = city["border_continuity"]["share"]
        typer.echo(
            f"{city['city_dir']}: {city['tiles']} tile(s) of split {split}, {city['boundaries']} boundaries"
            + (f"; {share:.0%} of boundary ends at shared tile edges continue" if share is not None else "")
        )
    missing = report["missing_patches"]
    typer.echo(
        f"{out}: {len(report['tiles_written'])} tile(s) written; {len(missing)} missing patch(es)"
        + (f": {', '.join(missing[:10])}{' ...' if len(missing) > 10 else ''}" if missing else "")
    )


def import_masks_cmd(
    source: Path = typer.Argument(..., help="Folder of images and their label masks."),
    out: Path = typer.Option(..., "--out", help="Folder for one city per image, plus set.json listing them."),
    gsd: Optional[float] = typer.Option(
        None,
        callback=positive,
        help="Pixel size in metres of images without a georeference; a georeferenced image's CRS gives "
        "its own, and a --gsd more than 2 % off it is refused.",
    ),
    target_gsd: float = typer.Option(
        0.152, callback=positive, help="Pixel size to resample to (the shipped model's: 0.152 m)."
    ),
    image_pattern: str = typer.Option(
        "{id}_image.png", help="Image file names; {id} is the part shared with the mask."
    ),
    mask_pattern: str = typer.Option("{id}_edge.png", help="Mask file names."),
    kind: str = typer.Option("edge", help="edge: the mask marks road-edge lines | surface: it marks the road surface."),
    channel: int = typer.Option(1, min=1, help="Band of the mask file to read (1-based)."),
    threshold: float = typer.Option(128, callback=finite, help="Mask pixels above this value are labelled."),
    invert: bool = typer.Option(
        False, "--invert", help="Label pixels below the threshold instead (dark lines on white)."
    ),
    ids: Optional[str] = typer.Option(None, help="Comma-separated ids to import (default: every pair found)."),
    quiet: QuietOption = False,
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
        raise typer.BadParameter(str(exc)) from None
    out_dir(out)
    report = import_masks(
        source,
        out,
        gsd=gsd,
        rule=rule,
        image_pattern=image_pattern,
        mask_pattern=mask_pattern,
        target_gsd=target_gsd,
        ids=ids.split(",") if ids else None,
        progress=not quiet,
    )
    total = sum(c["boundaries"] for c in report["cities"])
    typer.echo(
        f"{out}: {len(report['cities'])} cities, {total} boundary lines, at {target_gsd:g} m/px (set.json lists them)"
    )


def make_city_cmd(
    tiles: list[Path] = typer.Argument(..., help="GeoTIFF tile(s) or a folder of them (one pixel grid, one CRS)."),
    ground_truth: Path = typer.Option(
        ..., "--ground-truth", help="Road boundaries as lines (GeoPackage, GeoJSON, Shapefile...) with a CRS."
    ),
    out: Path = typer.Option(..., "--out", help="City directory to write (tiles are linked, not copied)."),
) -> None:
    """Your own GeoTIFFs + vector road boundaries -> a city directory, for evaluate-model,
    evaluate-set, benchmark --city and training (extra_train_cities)."""
    from csboundary.data.user_city import make_city

    no_file_at(out)
    meta = make_city(tiles, ground_truth, out)
    typer.echo(
        f"{out}: {len(meta['tiles'])} tile(s), {meta['width']}x{meta['height']} px at {meta['pixel_m']:.3g} m, "
        f"{meta['boundaries']} boundaries"
    )


def labels(
    city: Path = typer.Argument(..., help="A city directory (from `csboundary synth` or `import-topo-boundary`)."),
    out: Path = typer.Option(..., "--out", help="Output folder for per-patch labels."),
    core: int = typer.Option(1000, min=16, help="Patch core size, px (paper: 1000)."),
    margin: int = typer.Option(50, min=0, help="Patch margin on every side, px (paper: 50)."),
    aux_spacing: int = typer.Option(250, min=0, help="Auxiliary keypoint grid spacing, px (0 = none)."),
    segmentation_width: int = typer.Option(3, min=1, help="Boundary width in the segmentation label, px."),
    heat_sigma: float = typer.Option(3.0, callback=finite, min=0.1, help="Gaussian sigma of the keypoint map, px."),
    quiet: QuietOption = False,
) -> None:
    """Write every patch's training labels: segmentation, orientation, keypoint map, graph."""
    from csboundary.data.grid import GridConfig
    from csboundary.labels.config import LabelConfig
    from csboundary.labels.writer import write_city_labels

    config = LabelConfig(
        grid=GridConfig(core, margin),
        aux_spacing_px=aux_spacing,
        segmentation_width=segmentation_width,
        heat_sigma_px=heat_sigma,
    )
    out_dir(out)
    manifest = write_city_labels(city, out, config, progress=not quiet)
    c = manifest["counts"]
    typer.echo(
        f"{out}: {c['patches']} patches, {c['vertices']} vertices, {c['edges']} edges ({c['corner_edges']} corner) in "
        f"{manifest['seconds']['total']:.1f} s"
    )


def show(
    inputs: list[Path] = typer.Argument(..., help="A city directory, GeoTIFF tile(s), or a directory of tiles."),
    out: Path = typer.Option(..., "--out", help="PNG to write."),
    window: Optional[str] = typer.Option(None, help="Pixel window COL,ROW,WIDTH,HEIGHT in mosaic pixels."),
    bounds: Optional[str] = typer.Option(None, help="World window MINX,MINY,MAXX,MAXY in the mosaic's CRS."),
    ground_truth: Optional[Path] = typer.Option(
        None, help="Boundaries to draw (GeoPackage/GeoJSON); a city's own by default."
    ),
    max_size: int = typer.Option(2000, min=16, help="Downsample so the longest side is at most this many pixels."),
    grid: bool = typer.Option(False, help="Draw the patch grid (cores red, 1100 px expanded windows yellow)."),
    labels: Optional[Path] = typer.Option(
        None, help="A folder from `csboundary labels`: draw one patch's labels (needs --patch)."
    ),
    patch: Optional[str] = typer.Option(
        None, help="Patch ROW,COL of the grid: the window becomes its 1100x1100 expanded window."
    ),
) -> None:
    """Draw a window of the imagery with road boundaries (or a patch's labels) over it."""
    from csboundary.data.grid import GridConfig
    from csboundary.data.inputs import open_imagery
    from csboundary.data.windows import PixelWindow
    from csboundary.pipeline.outputs.show import labels_grid, patch_of, render_patch_labels, render_view
    from csboundary.viz.overlay import write_png

    if sum(x is not None for x in (window, bounds, patch)) > 1:
        raise typer.BadParameter("give one of --window, --bounds, --patch")
    if labels is not None and patch is None:
        raise typer.BadParameter("--labels needs --patch ROW,COL")
    out_file(out, (".png",))
    mosaic, lines = open_imagery(inputs, ground_truth)
    area = None
    if patch is not None:
        row, col = parse_numbers(patch, 2, "--patch", "ROW,COL", int)
        try:
            the_patch = patch_of(mosaic, row, col, labels_grid(labels) if labels is not None else GridConfig())
        except ValueError as exc:
            raise typer.BadParameter(str(exc), param_hint="--patch") from None
        if labels is not None:
            rgb, graph = render_patch_labels(mosaic, labels, the_patch)
            write_png(out, rgb)
            typer.echo(f"{out}: labels of patch {row},{col}: {graph.n_vertices} vertices, {graph.n_edges} edges")
            return
        area = the_patch.expanded
    elif window:
        c, r, w, h = parse_numbers(window, 4, "--window", "COL,ROW,WIDTH,HEIGHT", int)
        if w <= 0 or h <= 0:
            raise typer.BadParameter("width and height must be positive", param_hint="--window")
        area = PixelWindow(c, r, w, h)
    world = tuple(parse_numbers(bounds, 4, "--bounds", "MINX,MINY,MAXX,MAXY")) if bounds else None
    rgb, drawn = render_view(
        mosaic, lines, area, world, max_size=max_size, grid=grid, source=inputs[0], lines_source=ground_truth
    )
    write_png(out, rgb)
    typer.echo(f"{out}: {drawn.width}x{drawn.height} px window, {len(lines)} boundaries")
