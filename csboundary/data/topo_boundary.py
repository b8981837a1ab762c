"""Read the Topo-boundary dataset (NYC) and turn it into csboundary city directories.

The benchmark cuts every 5000x5000 orthophoto tile into 25 patches ``TTTTTT_RC.tiff`` (6-digit
tile id, R = row block from the top, C = column block) with per-patch boundary labels
``labels/dense_seq/{id}.json`` in patch pixels ``[row, col]``. csBoundary works on whole tiles and
vector ground truth, so this module puts the patches back together, re-joins the boundaries that
the cut split at patch borders, and writes each tile as a city (see :mod:`csboundary.data.city`).

Choices, because the format leaves them open:

* Images and labels are found by searching the given root recursively, because users unpack the
  archives into different folders (the benchmark uses ``dataset/cropped_tiff`` and
  ``dataset/labels``).
* The benchmark's patches were saved without georeference (the tile id is the only link to the
  map). A georeference in the files is used when present; otherwise the tile is placed at
  0.5 US ft/px in EPSG:2263 with its top-left corner at (0, 0) and a warning.
* Every pixel of a present patch is valid. Patch masks are ignored on purpose: the benchmark's
  TIFFs mark band 4 (NIR) as alpha, so a mask derived from it would drop every pixel with NIR 0.
* Missing patches (the benchmark dropped many, e.g. all ``pretrain`` images) are masked invalid and
  reported. Their labels, when present, are still imported: ground truth describes the ground,
  not the imagery, and consumers mask by the tile's validity.
* Patch size and split count are parameters (defaults 1000 and 5) so tests can fabricate tiny
  files in exactly the same format.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import geopandas as gpd
import numpy as np
import rasterio
from affine import Affine
from rasterio.crs import CRS
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError
from scipy.spatial import cKDTree
import shapely
from shapely.geometry import LineString
from tqdm import tqdm

from csboundary.data.city import begin_city, ground_truth_path, tiles_dir, write_meta
from csboundary.data.geotiff import write_geotiff
from csboundary.data.ground_truth import write_ground_truth
from csboundary.data.raster import BANDS, NIR_FILL_BAND
from csboundary.data.windows import pixel_to_world
from csboundary.errors import InputError, InputWarning

SOURCE = "topo-boundary"
PATCH_SIZE = 1000
SPLITS = 5
FALLBACK_CRS = "EPSG:2263"  # NY State Plane Long Island, US survey feet: the NYC orthophotos' CRS
FALLBACK_GSD = 0.5  # US ft per pixel of the 2016 NYC orthophotos
SIMPLIFY_PX = 0.5  # staircase pixel chains -> straight runs (see pixels_to_line)
SMOOTH_PIXELS = 5
JOIN_TOLERANCE = 1.5  # px; > sqrt(2) so diagonal neighbours across a border are joined
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
        candidates = sorted((p for p in _walk(root) if p.name == SPLIT_FILE and p.is_file()), key=lambda p: (len(p.parts), str(p)))
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
                    raise InputError(path, f"is {width}x{height} px; Topo-boundary patches are {patch_size}x{patch_size}")
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


def _inside_patch(seq: np.ndarray, patch_size: int) -> np.ndarray:
    return ((seq >= -LABEL_MARGIN) & (seq <= patch_size + LABEL_MARGIN)).all(axis=1)


def clip_to_patch(seq: np.ndarray, patch_size: int) -> list[np.ndarray]:
    """The parts of a ``[row, col]`` label inside its patch (plus :data:`LABEL_MARGIN`): a point
    thousands of pixels away is an annotation error, and kept it would make every later raster
    of the tile as large as its coordinates."""
    if _inside_patch(seq, patch_size).all():
        return [seq]
    if len(seq) == 1:
        return []
    low, high = -LABEL_MARGIN, patch_size + LABEL_MARGIN
    clipped = shapely.clip_by_rect(LineString(seq), low, low, high, high)
    return [np.asarray(part.coords) for part in getattr(clipped, "geoms", [clipped]) if isinstance(part, LineString) and not part.is_empty]


# -- georeference (pure) ----------------------------------------------------------------------------
def fallback_transform(gsd: float = FALLBACK_GSD) -> Affine:
    """Pixel coordinates scaled to feet, tile top-left at (0, 0), y up (north-up like a real map)."""
    return Affine(gsd, 0.0, 0.0, 0.0, -gsd, 0.0)


def tile_georeference(patches: list[Patch], patch_size: int = PATCH_SIZE) -> tuple[Affine, str, bool]:
    """``(transform, crs, georeferenced)`` of the tile the ``patches`` belong to.

    Each georeferenced patch implies a tile origin (its own origin moved back by its block offset);
    they must all agree to a hundredth of a pixel, or the files do not form one tile.
    """
    geo = [p for p in patches if p.georeferenced]
    if not geo:
        return fallback_transform(), FALLBACK_CRS, False
    first = geo[0]
    bare = [p for p in patches if not p.georeferenced]
    if bare:
        raise InputError(bare[0].path, f"has no georeference, but {first.path} of the same tile has")
    ref = _tile_transform(first, patch_size)
    for patch in geo:
        t = patch.transform
        if t.b != 0 or t.d != 0 or t.a <= 0 or t.e >= 0:
            raise InputError(patch.path, "rotated or not north-up georeference is not supported")
        if patch.crs != first.crs:
            raise InputError(patch.path, f"CRS {patch.crs} differs from {first.crs} of {first.path}")
        tt = _tile_transform(patch, patch_size)
        tol = 0.01 * abs(ref.a)
        if not all(math.isclose(u, v, rel_tol=1e-9, abs_tol=tol) for u, v in zip(tt[:6], ref[:6])):
            raise InputError(
                patch.path,
                f"georeference puts the tile origin at ({tt.c:.3f}, {tt.f:.3f}), "
                f"but {first.path} puts it at ({ref.c:.3f}, {ref.f:.3f})",
            )
    return ref, first.crs.to_string(), True


GRID_FT = 2500.0  # NYC orthophoto tiles: 5000 px at 0.5 ft


def tile_origin_ft(tile_id: str, grid_ft: float = GRID_FT) -> tuple[float, float] | None:
    """South-west corner (easting, northing) in EPSG:2263 feet that a 6-digit tile id encodes.

    An inference from the benchmark's ids, not a documented fact: the first three digits read
    as easting / 1000 ft modulo 1000 (NYC spans 913,000-1,067,000 ft, so 000-499 means
    1,000,000 more), the last three as northing / 1000 ft, and tiles lie on a 2,500 ft grid, so
    the corner is the one grid line within the id's 1,000 ft. None when no grid line is (the id
    does not follow the pattern). ``import-topo-boundary --no-placement`` turns it off.
    """
    if not re.fullmatch(r"\d{6}", tile_id):
        return None
    east3, north3 = int(tile_id[:3]), int(tile_id[3:])
    out = []
    for low in (east3 * 1000.0 + (1_000_000.0 if east3 < 500 else 0.0), north3 * 1000.0):
        corner = math.ceil(low / grid_ft) * grid_ft
        if corner >= low + 1000.0:
            return None
        out.append(corner)
    return out[0], out[1]


def placed_transform(tile_id: str, gsd_ft: float = FALLBACK_GSD, size_px: int = PATCH_SIZE * SPLITS) -> Affine | None:
    """The tile's north-up transform in EPSG:2263 from :func:`tile_origin_ft` (None if it has none)."""
    corner = tile_origin_ft(tile_id)
    if corner is None:
        return None
    return Affine(gsd_ft, 0.0, corner[0], 0.0, -gsd_ft, corner[1] + size_px * gsd_ft)


def border_continuity(tiles: list["AssembledTile"], tolerance: float = 3.0, band: float = 2.0) -> dict[str, Any]:
    """How well the placement lets boundaries continue across shared tile edges.

    For each boundary end within ``band`` px of a tile edge that a neighbouring tile shares, is
    there an end of a boundary of the neighbour within ``tolerance`` px of it? A wrong placement
    leaves almost every border end alone; the right one matches most (a few end at a missing
    patch). Returns ``{"border_ends": n, "matched": m, "share": m / n}`` (share None without ends).
    """
    if not tiles:
        return {"border_ends": 0, "matched": 0, "share": None}
    gsd = tiles[0].transform.a
    west = min(t.transform.c for t in tiles)
    north = max(t.transform.f for t in tiles)
    ends, owner, near_edge = [], [], []
    boxes = {}
    for k, tile in enumerate(tiles):
        size = tile.patch_size * tile.splits
        off = np.array([(north - tile.transform.f) / gsd, (tile.transform.c - west) / gsd])
        boxes[k] = (off[0], off[1], off[0] + size, off[1] + size)
        for chain in tile.chains:
            for point in (chain[0], chain[-1]):
                local = point
                edge = min(local[0], local[1], size - 1 - local[0], size - 1 - local[1]) <= band
                ends.append(point + off)
                owner.append(k)
                near_edge.append(edge)
    ends, owner, near_edge = np.array(ends).reshape(-1, 2), np.array(owner), np.array(near_edge, dtype=bool)
    shared = np.zeros(len(ends), dtype=bool)
    for i in np.flatnonzero(near_edge):  # only ends on an edge some other tile lies beyond
        r, c = ends[i]
        shared[i] = any(k != owner[i] and b[0] - band - 1 <= r <= b[2] + band and b[1] - band - 1 <= c <= b[3] + band for k, b in boxes.items())
    if not shared.any():
        return {"border_ends": 0, "matched": 0, "share": None}
    tree = cKDTree(ends)
    matched = 0
    for i in np.flatnonzero(shared):
        partners = tree.query_ball_point(ends[i], tolerance)
        matched += any(owner[j] != owner[i] for j in partners)
    n = int(shared.sum())
    return {"border_ends": n, "matched": int(matched), "share": matched / n}


def join_tiles(tiles: list["AssembledTile"]) -> tuple[Affine, list[LineString], list[list[str]]]:
    """The tiles' boundaries in one frame, re-joined across shared tile edges: (transform of the
    frame's top-left, LineStrings in world coordinates, source tile ids per line)."""
    gsd = tiles[0].transform.a
    west = min(t.transform.c for t in tiles)
    north = max(t.transform.f for t in tiles)
    pieces = []
    for tile in tiles:
        off = np.array([round((north - tile.transform.f) / gsd), round((tile.transform.c - west) / gsd)], dtype=float)
        pieces.extend(Piece(tile.tile_id, chain + off) for chain in tile.chains)
    frame = Affine(gsd, 0.0, west, 0.0, -gsd, north)
    joined = join_pieces(pieces)
    return frame, [pixels_to_line(frame, points) for points, _ in joined], [sources for _, sources in joined]


def _tile_transform(patch: Patch, patch_size: int) -> Affine:
    return patch.transform @ Affine.translation(-patch.col * patch_size, -patch.row * patch_size)


# -- boundaries (pure) ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Piece:
    """One labelled boundary in tile pixels (``[row, col]``), and the patch it came from."""

    patch: str
    points: np.ndarray  # (n, 2) [row, col] in tile pixels


def join_pieces(pieces: list[Piece], tolerance: float = JOIN_TOLERANCE) -> list[tuple[np.ndarray, list[str]]]:
    """Re-join boundaries that the patch cut split: ``[(points [row, col], source patches)]``.

    An end of a piece is joined to an end of a piece from another patch when the two lie within
    ``tolerance`` px (they then sit on either side of a patch border); the closest pairs are joined
    first and each end joins at most once, so chains never fork. Pieces chain in both directions
    from the earliest piece, keeping its orientation; chains whose ends join close into rings.
    One-point pieces take part (a boundary can clip a patch corner by one pixel); chains with fewer
    than 2 distinct points are dropped.
    """
    if not pieces:
        return []
    ends = np.array([[p.points[0], p.points[-1]] for p in pieces], dtype=float).reshape(-1, 2)
    pairs = cKDTree(ends).query_pairs(tolerance + 1e-9, output_type="ndarray")
    pairs = [(i, j) for i, j in pairs.tolist() if pieces[i // 2].patch != pieces[j // 2].patch]
    pairs.sort(key=lambda ij: (float(np.hypot(*(ends[ij[0]] - ends[ij[1]]))), min(ij), max(ij)))
    link: dict[int, int] = {}  # end index (2 * piece + 0/1) -> joined end index
    for i, j in pairs:
        if i not in link and j not in link:
            link[i], link[j] = j, i

    visited = [False] * len(pieces)
    out = []
    for start in range(len(pieces)):
        if visited[start]:
            continue
        visited[start] = True
        chain: list[tuple[int, bool]] = [(start, True)]  # (piece, forward)
        closed = False
        end = 2 * start + 1  # walk forward from the start piece's last point
        while end in link:
            nxt = link[end]
            piece, entered = divmod(nxt, 2)
            if piece == start:
                closed = True
                break
            if visited[piece]:
                break
            visited[piece] = True
            chain.append((piece, entered == 0))
            end = 2 * piece + (1 - entered)
        if not closed:
            end = 2 * start  # and backward from its first point
            while end in link:
                piece, entered = divmod(link[end], 2)
                if visited[piece]:
                    break
                visited[piece] = True
                chain.insert(0, (piece, entered == 1))
                end = 2 * piece + (1 - entered)
        points = np.concatenate([pieces[k].points if fwd else pieces[k].points[::-1] for k, fwd in chain])
        if closed:
            points = np.concatenate([points, points[:1]])
        points = _drop_repeats(points)
        if len(points) < 2:
            continue
        sources = list(dict.fromkeys(pieces[k].patch for k, _ in chain))
        out.append((points, sources))
    return out


def _drop_repeats(points: np.ndarray) -> np.ndarray:
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.any(points[1:] != points[:-1], axis=1)
    return points[keep]


def pixels_to_line(transform: Affine, points: np.ndarray, simplify_px: float = SIMPLIFY_PX) -> LineString:
    """A LineString through the centres of tile pixels ``[row, col]`` in world coordinates.

    The labels are chains of every pixel, i.e. staircases whose direction jumps by 45 or 90
    degrees at each step; curvature keypoints need the boundary's real direction. So, unless
    ``simplify_px`` is 0, the chain is first averaged over ``SMOOTH_PIXELS`` consecutive pixels
    (ends kept; rings wrap), which removes the steps while moving a 40 px curb return by
    < 0.1 px, then simplified (Douglas-Peucker, ``simplify_px``).
    """
    xy = np.column_stack([points[:, 1] + 0.5, points[:, 0] + 0.5]).astype(float)
    if simplify_px > 0 and len(xy) > 2:
        xy = _smooth_chain(xy, SMOOTH_PIXELS)
        xy = np.asarray(LineString(xy).simplify(simplify_px, preserve_topology=True).coords)
    xs, ys = pixel_to_world(transform, xy[:, 0], xy[:, 1])
    return LineString(np.column_stack([xs, ys]))


def _smooth_chain(xy: np.ndarray, window: int) -> np.ndarray:
    """Moving average along a chain; rings (first == last) wrap, open chains keep their ends."""
    half = window // 2
    if len(xy) <= window:
        return xy
    closed = np.array_equal(xy[0], xy[-1])
    body = xy[:-1] if closed else xy
    kernel = np.ones(window) / window
    if closed:
        padded = np.concatenate([body[-half:], body, body[:half]])
        out = np.column_stack([np.convolve(padded[:, k], kernel, mode="valid") for k in (0, 1)])
        return np.vstack([out, out[:1]])
    out = body.copy()
    out[half:-half] = np.column_stack([np.convolve(body[:, k], kernel, mode="valid") for k in (0, 1)])
    return out


# -- one tile ---------------------------------------------------------------------------------------
@dataclass
class AssembledTile:
    """A whole tile rebuilt from its patches, with its boundaries as world-coordinate LineStrings."""

    tile_id: str
    image: np.ndarray  # (4, H, W) uint8, 0 where no patch
    valid: np.ndarray  # (H, W) bool, False where a patch is missing
    transform: Affine
    crs: str
    georeferenced: bool
    patch_size: int
    splits: int
    patches: dict[str, Path]  # present patch id -> file
    missing: list[str]  # patch ids without an image
    unlabelled: list[str]  # present patch ids without a label file
    lines: list[LineString] = field(default_factory=list)
    line_sources: list[list[str]] = field(default_factory=list)  # patch ids each line came from
    chains: list[np.ndarray] = field(default_factory=list)  # the lines as joined [row, col] tile pixels
    placed: bool = False  # put on the map from its tile id (:func:`placed_transform`)

    @property
    def gsd(self) -> float:
        return float(self.transform.a)

    def ground_truth(self) -> gpd.GeoDataFrame:
        """The boundaries as the project's ground-truth frame (``source_patch``: comma-separated ids)."""
        return gpd.GeoDataFrame(
            {
                "source_patch": np.array([",".join(s) for s in self.line_sources], dtype=object),
                "tile_id": np.array([self.tile_id] * len(self.lines), dtype=object),
            },
            geometry=gpd.GeoSeries(self.lines, crs=self.crs),
            crs=self.crs,
        )


def assemble_tile(index: TopoBoundaryIndex, tile_id: str, patch_size: int = PATCH_SIZE, splits: int = SPLITS,
                  placement: bool = True) -> AssembledTile:
    """Reassemble tile ``tile_id``: patch (R, C) goes to rows R*ps.., cols C*ps..; boundaries re-joined.
    Without a georeference in the files, ``placement`` puts it on the map from its id."""
    _check_grid(patch_size, splits)
    found = index.patches.get(tile_id, {})
    for (row, col), path in found.items():
        if row >= splits or col >= splits:
            raise InputError(path, f"block {row}{col} lies outside the {splits}x{splits} split")
    size = patch_size * splits
    image = np.zeros((BANDS, size, size), dtype=np.uint8)
    valid = np.zeros((size, size), dtype=bool)
    read: list[Patch] = []
    for (row, col), path in sorted(found.items()):
        patch = read_patch(path, row, col, patch_size)
        rows = slice(row * patch_size, (row + 1) * patch_size)
        cols = slice(col * patch_size, (col + 1) * patch_size)
        image[:, rows, cols] = patch.pixels
        valid[rows, cols] = True
        read.append(patch)
    transform, crs, georeferenced = tile_georeference(read, patch_size)
    placed = False
    if not georeferenced and placement and placed_transform(tile_id, FALLBACK_GSD, patch_size * splits) is not None:
        transform, placed = placed_transform(tile_id, FALLBACK_GSD, patch_size * splits), True
    elif not georeferenced:
        where = read[0].path if read else tile_id
        warnings.warn(
            f"{where}: tile {tile_id} is not georeferenced; placed at {FALLBACK_GSD} ft/px in {FALLBACK_CRS} "
            "with its top-left corner at (0, 0) (tile id recorded)",
            InputWarning,
            stacklevel=2,
        )

    all_ids = [patch_id(tile_id, r, c) for r in range(splits) for c in range(splits)]
    present = {patch_id(tile_id, r, c): p for (r, c), p in sorted(found.items())}
    missing = [pid for pid in all_ids if pid not in present]
    unlabelled = [pid for pid in present if pid not in index.labels]
    pieces = []
    for pid in all_ids:
        if pid in index.labels:
            _, row, col = parse_patch_id(pid)
            offset = np.array([row * patch_size, col * patch_size], dtype=float)
            seqs = read_dense_seq(index.labels[pid])
            kept = [part for seq in seqs if len(seq) for part in clip_to_patch(seq, patch_size)]
            outside = sum(int((~_inside_patch(seq, patch_size)).sum()) for seq in seqs)
            if outside:
                warnings.warn(f"{index.labels[pid]}: {outside} label point(s) lie more than {LABEL_MARGIN:g} px outside the "
                              f"{patch_size} px patch; the boundaries are clipped to it", InputWarning, stacklevel=2)
            pieces.extend(Piece(pid, part + offset) for part in kept)
    joined = join_pieces(pieces)
    lines = [pixels_to_line(transform, points) for points, _ in joined]
    return AssembledTile(
        tile_id, image, valid, transform, crs, georeferenced, patch_size, splits, present, missing, unlabelled,
        lines, [sources for _, sources in joined], [points for points, _ in joined], placed,
    )


def _check_grid(patch_size: int, splits: int) -> None:
    if patch_size < 1:
        raise ValueError(f"patch_size must be >= 1, got {patch_size}")
    if not 1 <= splits <= 10:
        raise ValueError(f"splits must be 1..10 (one digit per block index), got {splits}")


# -- writing cities ---------------------------------------------------------------------------------
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
    _check_grid(patch_size, splits)
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
        gt = gpd.GeoDataFrame({"source_tiles": np.array([",".join(s) for s in sources], dtype=object)},
                              geometry=gpd.GeoSeries(lines, crs=FALLBACK_CRS), crs=FALLBACK_CRS)
        write_ground_truth(ground_truth_path(city_dir), gt)
        continuity = border_continuity(members)
        if continuity["share"] is not None and continuity["share"] < 0.5:
            warnings.warn(f"{city_dir}: only {continuity['matched']} of {continuity['border_ends']} boundary ends at shared tile edges "
                          "continue in the neighbour: the placement from tile ids is probably wrong (--no-placement)", InputWarning, stacklevel=2)
        write_meta(city_dir, {
            "source": SOURCE, "split": split, "crs": FALLBACK_CRS, "gsd": FALLBACK_GSD, "units": "US survey foot",
            "tiles": names, "tile_ids": [t.tile_id for t in members], "boundaries": len(lines),
            "placement": "from tile ids (an inference: csboundary.data.topo_boundary.tile_origin_ft)",
            "border_continuity": continuity, "transform": list(frame)[:6],
        })
        report[split] = {"city_dir": str(city_dir), "tiles": len(members), "boundaries": len(lines), "border_continuity": continuity}
    return report
