"""Writing Topo-boundary tiles as csBoundary cities: one city per tile, one per benchmark split
of the placed tiles, and the import that drives both and reports what was missing.

The only part of the package that writes files (see :mod:`csboundary.data.city_layout` for the layout).
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any, Iterable

import geopandas as gpd
import numpy as np
from rasterio.crs import CRS
from tqdm import tqdm

from csboundary.data.city_layout import begin_city, ground_truth_path, tiles_dir, write_meta
from csboundary.data.geotiff import write_geotiff
from csboundary.data.ground_truth import write_ground_truth
from csboundary.data.topo_boundary.files import PATCH_SIZE, SPLITS, TopoBoundaryIndex, check_grid, patch_id, scan
from csboundary.data.topo_boundary.placement import FALLBACK_CRS, FALLBACK_GSD
from csboundary.data.topo_boundary.seams import border_continuity, join_tiles
from csboundary.data.topo_boundary.tiles import AssembledTile, assemble_tile
from csboundary.errors import InputError, InputWarning

SOURCE = "topo-boundary"


def tile_file_name(tile_id: str) -> str:
    """Named after the tile id so georeferenced tiles of several cities can share one folder."""
    return f"{tile_id}.tif"


def write_tile_city(tile: AssembledTile, city_dir: str | Path, index: TopoBoundaryIndex) -> Path:
    """Write one assembled tile as a city directory; ``city.json`` last marks it finished."""
    city_dir = begin_city(city_dir)
    tags = {
        "source": SOURCE,
        "tile_id": tile.tile_id,
        "georeferenced": str(tile.georeferenced).lower(),
        "patch_size": str(tile.patch_size),
        "splits": str(tile.splits),
        "missing_patches": ",".join(tile.missing),
    }
    name = tile_file_name(tile.tile_id)
    write_geotiff(tiles_dir(city_dir) / name, tile.image, tile.transform, tile.crs, valid=tile.valid, tags=tags)
    write_ground_truth(ground_truth_path(city_dir), tile.ground_truth())
    all_ids = [patch_id(tile.tile_id, r, c) for r in range(tile.splits) for c in range(tile.splits)]
    crs = CRS.from_user_input(tile.crs)
    meta: dict[str, Any] = {
        "source": SOURCE,
        "tile_id": tile.tile_id,
        "crs": tile.crs,
        "gsd": tile.gsd,
        "units": crs.linear_units,
        "georeferenced": tile.georeferenced,
        "transform": list(tile.transform)[:6],
        "width": int(tile.image.shape[2]),
        "height": int(tile.image.shape[1]),
        "tiles": [name],
        "patch_size": tile.patch_size,
        "splits": tile.splits,
        "patch_split": {pid: index.split.get(pid) for pid in all_ids},
        "patch_files": {pid: str(path) for pid, path in tile.patches.items()},
        "missing_patches": tile.missing,
        "unlabelled_patches": tile.unlabelled,
        "boundaries": len(tile.lines),
        "dataset_root": str(index.root),
        "split_file": str(index.split_file) if index.split_file else None,
        "notes": _notes(tile),
    }
    return write_meta(city_dir, meta)


def _notes(tile: AssembledTile) -> str:
    text = "Imported from Topo-boundary patches; patch_split is each patch's benchmark split (null: not listed)."
    if not tile.georeferenced:
        text += (
            f" Not georeferenced: pixel coordinates at {tile.gsd:g} ft/px in {tile.crs} with the tile's"
            " top-left at (0, 0); the tile id is the only link to the map."
        )
    return text


def import_topo_boundary(
    root: str | Path,
    out_dir: str | Path,
    patch_size: int = PATCH_SIZE,
    splits: int = SPLITS,
    progress: bool = True,
    *,
    tile_ids: Iterable[str] | None = None,
    placement: bool = True,
) -> dict[str, Any]:
    """Import every tile under ``root`` (or only ``tile_ids``) as ``out_dir/TTTTTT/`` cities and,
    when the tiles can be placed from their ids (``placement``), every split's tiles as one
    georeferenced city ``out_dir/city-<split>/`` with boundaries re-joined across tile edges:
    the paper's city-scale evaluation. The placement is checked on the labels (how many
    boundary ends at shared tile edges find a partner, :func:`border_continuity`) and reported.

    Missing patches and missing label files are reported, not fatal; a broken file raises an
    InputError naming it. Returns a JSON-serialisable report.
    """
    check_grid(patch_size, splits)
    index = scan(root)
    if not index.patches:
        raise InputError(root, "no Topo-boundary patches (TTTTTT_RC.tiff) found under this folder")
    wanted = index.tile_ids if tile_ids is None else list(tile_ids)
    unknown = [t for t in wanted if t not in index.patches]
    if unknown:
        raise InputError(root, f"no patches of tile(s) {', '.join(unknown)}")
    out_dir = Path(out_dir)
    report: dict[str, Any] = {
        "root": str(index.root),
        "out_dir": str(out_dir),
        "split_file": str(index.split_file) if index.split_file else None,
        "patch_size": patch_size,
        "splits": splits,
        "tiles_written": [],
        "missing_patches": [],
        "unlabelled_patches": [],
        "not_georeferenced": [],
        "label_tiles_without_images": index.label_tiles_without_images(),
        "tiles": {},
    }
    placed: list[AssembledTile] = []
    for tile_id in tqdm(wanted, desc="topo-boundary tiles", unit="tile", disable=not progress):
        tile = assemble_tile(index, tile_id, patch_size, splits, placement)
        city_dir = out_dir / tile_id
        write_tile_city(tile, city_dir, index)
        if tile.placed:  # keep the geometry only: a tile's pixels are 100 MB
            placed.append(dataclasses.replace(tile, image=tile.image[:, :1, :1], valid=tile.valid[:1, :1]))
        report["tiles_written"].append(tile_id)
        report["missing_patches"].extend(tile.missing)
        report["unlabelled_patches"].extend(tile.unlabelled)
        if not tile.georeferenced:
            report["not_georeferenced"].append(tile_id)
        report["tiles"][tile_id] = {
            "city_dir": str(city_dir),
            "patches": len(tile.patches),
            "missing_patches": tile.missing,
            "unlabelled_patches": tile.unlabelled,
            "boundaries": len(tile.lines),
            "georeferenced": tile.georeferenced,
            "placed_from_id": tile.placed,
            "crs": tile.crs,
        }
    report["split_cities"] = write_split_cities(placed, out_dir, index) if placement else {}
    return report


def tile_split(tile: AssembledTile, index: TopoBoundaryIndex) -> str:
    """The benchmark split most of the tile's patches belong to ("unlisted" when none is listed)."""
    splits = [index.split.get(pid) for pid in tile.patches]
    listed = [s for s in splits if s]
    return max(sorted(set(listed)), key=listed.count) if listed else "unlisted"


def write_split_cities(tiles: list[AssembledTile], out_dir: Path, index: TopoBoundaryIndex) -> dict[str, Any]:
    """One city per split of the placed tiles: their GeoTIFFs linked, boundaries re-joined across
    tile edges, the placement's border continuity in ``city.json`` (and warned about when most
    border ends stay alone, i.e. the tiles are probably misplaced)."""
    groups: dict[str, list[AssembledTile]] = {}
    for tile in tiles:
        groups.setdefault(tile_split(tile, index), []).append(tile)
    report = {}
    for split, members in sorted(groups.items()):
        city_dir = begin_city(out_dir / f"city-{split}")
        tiles_dir(city_dir).mkdir(parents=True, exist_ok=True)
        names = []
        for tile in members:
            name = tile_file_name(tile.tile_id)
            link = tiles_dir(city_dir) / name
            link.unlink(missing_ok=True)
            link.symlink_to(Path("..", "..", tile.tile_id, "tiles", name))
            names.append(name)
        frame, lines, sources = join_tiles(members)
        gt = gpd.GeoDataFrame(
            {"source_tiles": np.array([",".join(s) for s in sources], dtype=object)},
            geometry=gpd.GeoSeries(lines, crs=FALLBACK_CRS),
            crs=FALLBACK_CRS,
        )
        write_ground_truth(ground_truth_path(city_dir), gt)
        continuity = border_continuity(members)
        if continuity["share"] is not None and continuity["share"] < 0.5:
            warnings.warn(
                f"{city_dir}: only {continuity['matched']} of {continuity['border_ends']} boundary ends at shared tile edges "
                "continue in the neighbour: the placement from tile ids is probably wrong (--no-placement)",
                InputWarning,
                stacklevel=2,
            )
        write_meta(
            city_dir,
            {
                "source": SOURCE,
                "split": split,
                "crs": FALLBACK_CRS,
                "gsd": FALLBACK_GSD,
                "units": "US survey foot",
                "tiles": names,
                "tile_ids": [t.tile_id for t in members],
                "boundaries": len(lines),
                "placement": "from tile ids (an inference: csboundary.data.topo_boundary.tile_origin_ft)",
                "border_continuity": continuity,
                "transform": list(frame)[:6],
            },
        )
        report[split] = {
            "city_dir": str(city_dir),
            "tiles": len(members),
            "boundaries": len(lines),
            "border_continuity": continuity,
        }
    return report
