"""Reading the Topo-boundary files: patch names, finding images, labels and the split file under
a root, one patch's pixels and georeference, and its ``dense_seq`` labels.

The dataset's format rules (6-digit tile ids, one digit per block, patch size, bands, label
points) are checked here, where the files are read, so the modules that assemble tiles and
write cities work on data already known to be sound.
"""

from __future__ import annotations

import json
import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np
import rasterio
import shapely
from affine import Affine
from rasterio.crs import CRS
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError
from shapely.geometry import LineString

from csboundary.data.raster_files import BANDS, NIR_FILL_BAND
from csboundary.errors import InputError, InputWarning

PATCH_SIZE = 1000
SPLITS = 5
SPLIT_FILE = "data_split.json"
LABEL_DIR = "dense_seq"

_PATCH_RE = re.compile(r"^(\d{6})_(\d)(\d)$")
_IMAGE_SUFFIXES = (".tiff", ".tif")


# -- names ------------------------------------------------------------------------------------------
def patch_id(tile_id: str, row: int, col: int) -> str:
    """``"TTTTTT_RC"``: the patch at row block ``row``, column block ``col`` of a tile."""
    return f"{tile_id}_{row}{col}"


def parse_patch_id(text: str) -> tuple[str, int, int] | None:
    """``(tile_id, row, col)`` of a patch id (or file stem), or None if it is not one."""
    match = _PATCH_RE.match(text)
    if match is None:
        return None
    return match.group(1), int(match.group(2)), int(match.group(3))


def check_grid(patch_size: int, splits: int) -> None:
    if patch_size < 1:
        raise ValueError(f"patch_size must be >= 1, got {patch_size}")
    if not 1 <= splits <= 10:
        raise ValueError(f"splits must be 1..10 (one digit per block index), got {splits}")


# -- scanning ---------------------------------------------------------------------------------------
@dataclass
class TopoBoundaryIndex:
    """What :func:`scan` found under a dataset root; paths only, nothing is read yet."""

    root: Path
    patches: dict[str, dict[tuple[int, int], Path]]  # tile id -> (row, col) -> image file
    labels: dict[str, Path]  # patch id -> dense_seq JSON
    split: dict[str, str]  # patch id -> "train" / "valid" / "test" / "pretrain"
    split_file: Path | None = None

    @property
    def tile_ids(self) -> list[str]:
        return sorted(self.patches)

    def label_tiles_without_images(self) -> list[str]:
        """Tile ids that have labels but no image patch at all (they cannot be imported)."""
        ids = {parsed[0] for pid in self.labels if (parsed := parse_patch_id(pid))}
        return sorted(ids - set(self.patches))


def scan(root: str | Path, *, split_file: str | Path | None = None) -> TopoBoundaryIndex:
    """Find patch images, ``dense_seq`` labels and ``data_split.json`` anywhere under ``root``.

    A patch id found twice is an error (which copy is meant is unknowable). If several split files
    exist (the benchmark's re-split script writes a second one), the one nearest ``root`` is used
    with a warning, unless ``split_file`` names one.
    """
    root = Path(root)
    if not root.is_dir():
        raise InputError(root, "not a directory (expected the Topo-boundary dataset root)")
    patches: dict[str, dict[tuple[int, int], Path]] = {}
    found: dict[str, Path] = {}
    for path in sorted(_walk(root)):
        if path.suffix.lower() not in _IMAGE_SUFFIXES or not path.is_file():
            continue
        parsed = parse_patch_id(path.stem)
        if parsed is None:
            continue
        pid = path.stem
        if pid in found:
            raise InputError(path, f"patch {pid} found twice (also {found[pid]})")
        found[pid] = path
        tile_id, row, col = parsed
        patches.setdefault(tile_id, {})[(row, col)] = path

    labels: dict[str, Path] = {}
    for label_dir in sorted(p for p in _walk(root) if p.name == LABEL_DIR and p.is_dir()):
        for path in sorted(label_dir.glob("*.json")):
            if parse_patch_id(path.stem) is None or path.name.startswith("."):
                continue
            if path.stem in labels:
                raise InputError(path, f"labels of patch {path.stem} found twice (also {labels[path.stem]})")
            labels[path.stem] = path

    if split_file is None:
        candidates = sorted(
            (p for p in _walk(root) if p.name == SPLIT_FILE and p.is_file()), key=lambda p: (len(p.parts), str(p))
        )
        if len(candidates) > 1:
            warnings.warn(
                f"{candidates[0]}: using this {SPLIT_FILE}; also found {', '.join(map(str, candidates[1:]))}",
                InputWarning,
                stacklevel=2,
            )
        split_file = candidates[0] if candidates else None
    split = read_data_split(split_file) if split_file is not None else {}
    return TopoBoundaryIndex(root, patches, labels, split, Path(split_file) if split_file else None)


def _walk(root: Path) -> Iterable[Path]:
    """Every path under ``root`` except hidden ones (and what lies in hidden folders)."""
    for path in root.rglob("*"):
        if not any(part.startswith(".") for part in path.relative_to(root).parts):
            yield path


def read_data_split(path: str | Path) -> dict[str, str]:
    """Read ``data_split.json`` into ``{patch id: split name}``; the splits must be disjoint."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(path, f"unreadable split file ({str(exc).splitlines()[0]})") from exc
    if not isinstance(data, dict) or not all(isinstance(v, list) for v in data.values()):
        raise InputError(path, 'expected {"train": [...], "valid": [...], "test": [...], "pretrain": [...]}')
    split: dict[str, str] = {}
    for name, ids in data.items():
        for pid in ids:
            if not isinstance(pid, str):
                raise InputError(path, f"{name} lists {pid!r}, not a patch id string")
            if pid in split and split[pid] != name:
                raise InputError(path, f"patch {pid} is listed in both {split[pid]} and {name}")
            split[pid] = name
    return split


# -- reading one patch ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Patch:
    """Pixels and georeference of one patch file."""

    path: Path
    row: int
    col: int
    pixels: np.ndarray  # (4, patch_size, patch_size) uint8
    crs: CRS | None
    transform: Affine

    @property
    def georeferenced(self) -> bool:
        return self.crs is not None and self.transform != Affine.identity()


def read_patch(path: str | Path, row: int, col: int, patch_size: int = PATCH_SIZE) -> Patch:
    """Read a patch image; anything but a ``patch_size``-square, >= 3-band uint8 raster is an InputError.

    3-band files get NIR from the green band, as :class:`csboundary.data.raster.Mosaic` does.
    """
    path = Path(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as ds:
                count, dtype, width, height = ds.count, ds.dtypes[0], ds.width, ds.height
                crs, transform = ds.crs, ds.transform
                if (width, height) != (patch_size, patch_size):
                    raise InputError(
                        path, f"is {width}x{height} px; Topo-boundary patches are {patch_size}x{patch_size}"
                    )
                if count < 3:
                    raise InputError(path, f"has {count} band(s); need 4 (R, G, B, NIR) or at least 3 (R, G, B)")
                if dtype != "uint8":
                    raise InputError(path, f"data type {dtype}; Topo-boundary patches are uint8")
                pixels = ds.read(list(range(1, min(count, BANDS) + 1)))
    except RasterioIOError as exc:
        text = str(exc)
        if "not recognized" in text or "not a supported" in text.lower():
            raise InputError(path, "not a raster (GDAL does not recognise the format)") from exc
        raise InputError(path, f"unreadable raster ({text.splitlines()[0] if text else type(exc).__name__})") from exc
    if count == 3:
        warnings.warn(f"{path}: 3-band RGB patch; NIR is filled with the green band", InputWarning, stacklevel=2)
        pixels = np.concatenate([pixels, pixels[NIR_FILL_BAND : NIR_FILL_BAND + 1]], axis=0)
    elif count > BANDS:
        warnings.warn(f"{path}: {count} bands; using bands 1-4 as R, G, B, NIR", InputWarning, stacklevel=2)
    return Patch(path, row, col, pixels, crs, transform)


def _is_point(p) -> bool:
    return (
        isinstance(p, (list, tuple))
        and len(p) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in p)
    )


def read_dense_seq(path: str | Path) -> list[np.ndarray]:
    """Read a ``dense_seq`` label file into one (n, 2) float array of ``[row, col]`` per boundary."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(path, f"unreadable label file ({str(exc).splitlines()[0]})") from exc
    if not isinstance(data, list):
        raise InputError(path, 'expected a list of {"init_vertex", "end_vertex", "seq"} objects')
    seqs = []
    for k, item in enumerate(data):
        seq = item.get("seq") if isinstance(item, dict) else None
        if not isinstance(seq, list) or not all(_is_point(p) for p in seq):
            raise InputError(path, f"boundary {k} has no valid 'seq' list of [row, col] pairs")
        seqs.append(np.asarray(seq, dtype=float).reshape(-1, 2))
    return seqs


LABEL_MARGIN = 2.0  # px a label point may lie outside its patch (annotation on the border) before it is clipped


def inside_patch(seq: np.ndarray, patch_size: int) -> np.ndarray:
    return ((seq >= -LABEL_MARGIN) & (seq <= patch_size + LABEL_MARGIN)).all(axis=1)


def clip_to_patch(seq: np.ndarray, patch_size: int) -> list[np.ndarray]:
    """The parts of a ``[row, col]`` label inside its patch (plus :data:`LABEL_MARGIN`): a point
    thousands of pixels away is an annotation error, and kept it would make every later raster
    of the tile as large as its coordinates."""
    if inside_patch(seq, patch_size).all():
        return [seq]
    if len(seq) == 1:
        return []
    low, high = -LABEL_MARGIN, patch_size + LABEL_MARGIN
    clipped = shapely.clip_by_rect(LineString(seq), low, low, high, high)
    return [
        np.asarray(part.coords)
        for part in getattr(clipped, "geoms", [clipped])
        if isinstance(part, LineString) and not part.is_empty
    ]
