"""Import imagery labelled with raster masks (road-edge lines or road-surface areas) as cities.

Most public road datasets label with pictures, not vectors: an image plus a mask of the road
edge (lines 1-2 px wide) or of the road surface. This module turns each (image, mask) pair into a
city directory (:mod:`csboundary.data.city_layout`) with vector ground truth, resampled to the model's
pixel size, so ``evaluate-set``, ``evaluate-model`` and ``train`` (``extra_train_cities``) read it
like any other city.

Choices:

* A mask is one band of the mask file (``channel``) compared with ``threshold``; ``invert``
  marks pixels *below* it (e.g. red lines on white have a low green channel).
* ``edge`` masks are skeletonised and traced into polylines at their own resolution (a thin line
  does not survive resampling), then scaled; ``surface`` masks give their outline first (pixels
  of the surface with a neighbour outside it; the picture's border is not a road edge).
* Images and ground truth are resampled to ``target_gsd`` (default: the synthetic city's 0.152 m,
  the pixel size the shipped model was trained at): area averaging when shrinking, bicubic when
  enlarging.
* A georeferenced GeoTIFF keeps its CRS and origin; a plain picture is placed with its top-left
  corner at (0, 0) of EPSG:32618 (metres; the synthetic cities' CRS) and ``georeferenced: false``
  in ``city.json``: the ground truth and the prediction share that frame, so scores are right.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import geopandas as gpd
import numpy as np
import rasterio
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError
from scipy import ndimage
from shapely.geometry import LineString
from tqdm import tqdm

from csboundary.data.atomic import atomic_path
from csboundary.data.city_layout import begin_city, ground_truth_path, tile_name, tiles_dir, write_meta
from csboundary.data.folder_lock import locked_folder
from csboundary.data.geotiff import write_geotiff
from csboundary.data.ground_truth import write_ground_truth
from csboundary.data.units import GroundUnits, geometric_mean, ground_units, pixel_size_m
from csboundary.data.windows import pixel_to_world
from csboundary.errors import InputError
from csboundary.graph.skeleton_graph import SkeletonConfig, skeleton_graph

SOURCE = "mask-import"
PLACEHOLDER_CRS = "EPSG:32618"
SET_FILE = "set.json"
from csboundary.data.units import MODEL_GSD  # noqa: E402  (re-exported)


@dataclass(frozen=True)
class MaskRule:
    """How to read the label picture: which band, what threshold, edge lines or road surface."""

    kind: str = "edge"  # edge | surface
    channel: int = 0  # 0-based band of the mask file
    threshold: float = 128
    invert: bool = False  # the label is where the band is below the threshold
    min_length_px: float = 8.0  # traced pieces shorter than this (label specks) are dropped

    def __post_init__(self):
        if self.kind not in ("edge", "surface"):
            raise ValueError(f"mask kind must be edge or surface, got {self.kind!r}")


@contextmanager
def opened(path: str | Path) -> Iterator[rasterio.DatasetReader]:
    """The raster at ``path``, open; a file GDAL cannot read is an InputError naming it."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as src:
                yield src
    except RasterioIOError as exc:
        raise InputError(path, f"not a readable image ({str(exc).splitlines()[0]})") from exc


def georeference(src: rasterio.DatasetReader) -> tuple[Affine | None, str | None]:
    """An open raster's transform and CRS, both None when it has no georeference."""
    georeferenced = src.crs is not None and not src.transform.is_identity
    return (src.transform, src.crs.to_string()) if georeferenced else (None, None)


def read_picture(path: str | Path) -> tuple[np.ndarray, Affine | None, str | None]:
    """(bands, h, w) pixels of any raster GDAL reads, its transform and CRS (None when absent)."""
    with opened(path) as src:
        return src.read(), *georeference(src)


GSD_AGREEMENT = 0.02  # a --gsd within 2 % of a georeferenced image's own pixel size is the same size, rounded


def source_pixel_m(
    image_path: str | Path, transform: Affine | None, crs: str | None, units: GroundUnits, gsd: float | None
) -> tuple[float, float]:
    """(east, north) metres per pixel of an image: its georeference's when it has one (a ``gsd``
    that disagrees is refused, neither silently applied nor silently ignored), else ``gsd``."""
    if transform is None:
        if gsd is None or not np.isfinite(gsd) or gsd <= 0:
            raise InputError(image_path, "has no georeference: give its pixel size in metres (--gsd)")
        return gsd, gsd
    own = pixel_size_m(units, transform)
    if not all(np.isfinite(v) and v > 0 for v in own):
        raise InputError(
            image_path, f"its georeference gives no pixel size ({transform.a:g} x {transform.e:g}: rotated?)"
        )
    if gsd is not None and max(abs(v / gsd - 1) for v in own) > GSD_AGREEMENT:
        size = f"{own[0]:.4g} m" if abs(own[0] / own[1] - 1) <= GSD_AGREEMENT else f"{own[0]:.4g} x {own[1]:.4g} m"
        raise InputError(
            image_path,
            f"--gsd {gsd:g} m disagrees with the {size} pixel its CRS {crs} gives: leave --gsd out "
            "(it is for images without a georeference) or fix the georeference",
        )
    return own


def check_pixel_size(image_path: Path, gsd: float | None) -> None:
    """Refuse an image whose pixel size is unknown or contradicts ``gsd``, reading only its header:
    :func:`import_masks` checks every image this way before it writes any city."""
    with opened(image_path) as src:
        transform, crs = georeference(src)
        centre = transform @ (src.width / 2, src.height / 2) if transform is not None else None
    source_pixel_m(image_path, transform, crs, ground_units(crs or PLACEHOLDER_CRS, centre), gsd)


def label_mask(picture: np.ndarray, rule: MaskRule, path: str | Path = "<mask>") -> np.ndarray:
    """(h, w) bool: the pixels the rule marks in a label picture (bands, h, w)."""
    if not 0 <= rule.channel < len(picture):
        raise InputError(path, f"has {len(picture)} band(s); the mask rule reads band {rule.channel + 1}")
    band = picture[rule.channel].astype(np.float32)
    return band < rule.threshold if rule.invert else band > rule.threshold


def surface_outline(surface: np.ndarray) -> np.ndarray:
    """Pixels of ``surface`` with a 4-neighbour outside it, excluding the picture's border row
    and column (a road cut by the crop has no edge there)."""
    inner = ndimage.binary_erosion(surface, structure=ndimage.generate_binary_structure(2, 1), border_value=1)
    outline = surface & ~inner
    outline[[0, -1], :] = False
    outline[:, [0, -1]] = False
    return outline


def mask_polylines(mask: np.ndarray, rule: MaskRule) -> list[np.ndarray]:
    """Polylines (col, row) in the mask's pixel frame tracing the road edges a mask marks."""
    edges = surface_outline(mask) if rule.kind == "surface" else mask
    if not edges.any():
        return []
    config = SkeletonConfig(threshold=0.5, simplify_px=0.5, spur_px=4.0, min_length_px=rule.min_length_px)
    graph = skeleton_graph(edges.astype(np.float32), config)
    return [np.asarray(p, float) for p in graph.edge_polylines or [] if p is not None and len(p) >= 2]


def resample(image: np.ndarray, factor: tuple[float, float]) -> np.ndarray:
    """(bands, h, w) uint8 scaled by ``factor`` (columns, rows; >1 enlarges): area averaging to
    shrink, bicubic to enlarge. Two factors: degree pixels are not square on the ground."""
    h, w = image.shape[1:]
    size = (max(1, round(w * factor[0])), max(1, round(h * factor[1])))
    method = cv2.INTER_AREA if min(factor) < 1 else cv2.INTER_CUBIC
    return np.stack([cv2.resize(band, size, interpolation=method) for band in image])


@dataclass
class ImportedCity:
    name: str
    city_dir: Path
    boundaries: int
    size: tuple[int, int]
    source_m: float  # metres per pixel of the image as given (its georeference's, or --gsd)


def import_pair(
    image_path: Path,
    mask_path: Path,
    city_dir: Path,
    *,
    gsd: float | None,
    rule: MaskRule,
    target_gsd: float = MODEL_GSD,
    name: str | None = None,
) -> ImportedCity:
    """One (image, mask) pair -> one city directory at ``target_gsd``."""
    image, transform, crs = read_picture(image_path)
    if image.dtype != np.uint8:
        raise InputError(image_path, f"the networks take 8-bit imagery; got {image.dtype} (rescale to 0-255 first)")
    if len(image) not in (3, 4):
        raise InputError(image_path, f"{len(image)} band(s); expected RGB or R, G, B, NIR")
    picture, _, _ = read_picture(mask_path)
    if picture.shape[1:] != image.shape[1:]:
        raise InputError(
            mask_path,
            f"is {picture.shape[2]}x{picture.shape[1]} px; its image {image_path.name} is {image.shape[2]}x{image.shape[1]}",
        )
    out_crs = crs or PLACEHOLDER_CRS
    centre = transform @ (image.shape[2] / 2, image.shape[1] / 2) if transform is not None else None
    units = ground_units(out_crs, centre)  # the CRS's units may be feet or degrees: pixel sizes compare in metres
    source_m = source_pixel_m(image_path, transform, crs, units, gsd)
    factor = (source_m[0] / target_gsd, source_m[1] / target_gsd)
    lines = mask_polylines(label_mask(picture, rule, mask_path), rule)
    out_image = resample(image, factor) if max(abs(f - 1) for f in factor) > 1e-6 else image
    origin = (transform.c, transform.f) if transform is not None else (0.0, 0.0)
    out_transform = Affine(
        target_gsd / units.metres_per_unit[0], 0, origin[0], 0, -target_gsd / units.metres_per_unit[1], origin[1]
    )
    world = []
    for line in lines:
        xs, ys = pixel_to_world(out_transform, line[:, 0] * factor[0], line[:, 1] * factor[1])
        world.append(LineString(np.column_stack([xs, ys])))
    city_dir = begin_city(city_dir)
    write_geotiff(tiles_dir(city_dir) / tile_name(0, 0), out_image, out_transform, out_crs, tags={"source": SOURCE})
    frame = gpd.GeoDataFrame(
        {"kind": ["road_edge"] * len(world)}, geometry=gpd.GeoSeries(world, crs=out_crs), crs=out_crs
    )
    write_ground_truth(ground_truth_path(city_dir), frame)
    meta: dict[str, Any] = {
        "source": SOURCE,
        "image": str(image_path),
        "mask": str(mask_path),
        "mask_rule": asdict(rule),
        "source_gsd": geometric_mean(source_m),  # metres
        "gsd": out_transform.a,  # CRS units, as every city.json's
        "pixel_m": target_gsd,
        "crs": out_crs,
        "georeferenced": transform is not None,
        "transform": list(out_transform)[:6],
        "width": int(out_image.shape[2]),
        "height": int(out_image.shape[1]),
        "bands": int(len(out_image)),
        "tiles": [tile_name(0, 0)],
        "boundaries": len(world),
        "notes": "Imported from an image and a label mask by csboundary import-masks."
        + (
            ""
            if transform is not None
            else f" Not georeferenced: placed at (0, 0) of {out_crs} with the given pixel size."
        ),
    }
    write_meta(city_dir, meta)
    return ImportedCity(
        name or city_dir.name,
        city_dir,
        len(world),
        (int(out_image.shape[2]), int(out_image.shape[1])),
        geometric_mean(source_m),
    )


def find_pairs(source: Path, image_pattern: str, mask_pattern: str) -> list[tuple[str, Path, Path]]:
    """(id, image, mask) for every file matching ``image_pattern`` (``{id}`` marks the name part)
    whose mask ``mask_pattern`` exists beside it."""
    if "{id}" not in image_pattern or "{id}" not in mask_pattern:
        raise ValueError("image and mask patterns must both contain {id}")
    prefix, suffix = image_pattern.split("{id}", 1)
    pairs = []
    for image in sorted(source.glob(image_pattern.replace("{id}", "*"))):
        name = image.name
        ident = name[len(prefix) : len(name) - len(suffix) if suffix else None]
        mask = source / mask_pattern.replace("{id}", ident)
        if mask.exists():
            pairs.append((ident, image, mask))
    return pairs


def import_masks(
    source: str | Path,
    out_dir: str | Path,
    *,
    gsd: float | None,
    rule: MaskRule = MaskRule(),
    image_pattern: str = "{id}_image.png",
    mask_pattern: str = "{id}_edge.png",
    target_gsd: float = MODEL_GSD,
    ids: list[str] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Import every (image, mask) pair under ``source`` (only ``ids`` when given) as
    ``out_dir/<id>/`` and list them in ``out_dir/set.json`` (written last: the set a later
    ``evaluate-set`` reads). Cities already listed there stay, so pairs that need another mask
    rule can be added by a second import into the same folder."""
    source, out_dir = Path(source), Path(out_dir)
    if not source.is_dir():
        raise InputError(source, "not a folder")
    pairs = find_pairs(source, image_pattern, mask_pattern)
    if ids is not None:
        unknown = sorted(set(ids) - {p[0] for p in pairs})
        if unknown:
            raise InputError(source, f"no image/mask pair for id(s) {', '.join(unknown)}")
        pairs = [p for p in pairs if p[0] in set(ids)]
    if not pairs:
        raise InputError(source, f"no image matching {image_pattern!r} with a mask {mask_pattern!r}")
    for _, image, _ in pairs:  # a pixel size unknown or contradicted stops the import before any city is written
        check_pixel_size(image, gsd)
    with locked_folder(out_dir):  # two imports into one set at once would each list only their own cities
        cities = []
        for ident, image, mask in tqdm(pairs, desc="import masks", unit="image", disable=not progress):
            cities.append(
                import_pair(image, mask, out_dir / ident, gsd=gsd, rule=rule, target_gsd=target_gsd, name=ident)
            )
        listing = out_dir / SET_FILE
        earlier = json.loads(listing.read_text()).get("cities", []) if listing.exists() else []
        new = [
            {
                "name": c.name,
                "dir": c.city_dir.name,
                "boundaries": c.boundaries,
                "size": list(c.size),
                "source": str(source),
                "source_gsd": c.source_m,
                "mask_rule": asdict(rule),
            }
            for c in cities
        ]
        names = {c["dir"] for c in new}
        report = {"target_gsd": target_gsd, "cities": [c for c in earlier if c.get("dir") not in names] + new}
        with atomic_path(listing) as tmp:
            tmp.write_text(json.dumps(report, indent=1) + "\n")
    return report
