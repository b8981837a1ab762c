"""A static review page for a prediction: imagery at full resolution, the boundaries coloured by
confidence, the doubtful edges first, and edits a person exports as GeoJSON.

``write_review_page`` writes a folder that opens from disk (``index.html``) or any static web
server, with nothing fetched from the network: the page's script and style ship with the package
(``viz/static``), the data is a script (``data.js``, since browsers refuse ``fetch`` on file://),
and the imagery is an image pyramid of 512 px JPEG tiles (level 0 = full resolution, each level
half the one below) so a city opens as fast as a patch. Coordinates on the page are the
mosaic's pixels; the graph's vertices and the ground truth are brought into them through their
world coordinates, and the edits go out in the graph's CRS (``apply-review`` reads them).
"""

from __future__ import annotations

import json
import math
import shutil
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from csboundary.data.atomic import atomic_path
from csboundary.data.footprint import cells_meeting
from csboundary.data.raster import Mosaic
from csboundary.data.windows import PixelWindow, pixel_to_world, world_to_pixel
from csboundary.graph.boundaries import graph_boundaries
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.viz.overlay import to_display

TILE = 512
JPEG_QUALITY = 85
STATIC = ("review.html", "review.js", "review.css")


def pyramid_levels(width: int, height: int, tile: int = TILE) -> int:
    """Levels until the whole image fits one tile (at least 1)."""
    return 1 + max(0, math.ceil(math.log2(max(width, height) / tile))) if max(width, height) > tile else 1


def pyramid_tiles(mosaic: Mosaic) -> list[tuple[int, int]]:
    """The (row, col) of every level-0 tile under the mosaic's footprint, row-major: groups of
    tiles kilometres apart get the tiles over them, not over the gaps between them."""
    return cells_meeting(mosaic.footprint, TILE, math.ceil(mosaic.height / TILE), math.ceil(mosaic.width / TILE))


def write_pyramid(mosaic: Mosaic, folder: Path, progress: bool = True) -> int:
    """``folder/L/R_C.jpg`` tiles of every level; level 0 read from the mosaic one tile at a time,
    each higher level from the four tiles below it. Tiles with no imagery under them are not
    written (the page draws nothing there). Returns the number of levels."""
    levels = pyramid_levels(mosaic.width, mosaic.height)
    width, height = mosaic.width, mosaic.height
    made = pyramid_tiles(mosaic)
    bar = tqdm(total=len(made), desc="review tiles", unit="tile", disable=not progress)
    (folder / "0").mkdir(parents=True, exist_ok=True)
    for r, c in made:
        win = PixelWindow(c * TILE, r * TILE, min(TILE, width - c * TILE), min(TILE, height - r * TILE))
        read = mosaic.read(win)
        cv2.imwrite(
            str(folder / "0" / f"{r}_{c}.jpg"),
            to_display(read.data, read.valid)[:, :, ::-1],
            [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY],
        )
        bar.update(1)
    bar.close()
    heights = [min(TILE, height - r * TILE) for r in range(math.ceil(height / TILE))]  # px of each tile row and column
    widths = [min(TILE, width - c * TILE) for c in range(math.ceil(width / TILE))]
    for level in range(1, levels):
        (folder / str(level)).mkdir(exist_ok=True)
        below, made = set(made), sorted({(r // 2, c // 2) for r, c in made})
        for r, c in made:
            rows = heights[2 * r : 2 * r + 2]
            cols = widths[2 * c : 2 * c + 2]
            image = np.zeros(
                (sum(rows), sum(cols), 3), np.uint8
            )  # a child without imagery stays black, as no-data does
            for dr in range(len(rows)):
                for dc in range(len(cols)):
                    if (2 * r + dr, 2 * c + dc) in below:
                        child = cv2.imread(str(folder / str(level - 1) / f"{2 * r + dr}_{2 * c + dc}.jpg"))
                        image[dr * rows[0] : dr * rows[0] + rows[dr], dc * cols[0] : dc * cols[0] + cols[dc]] = child
            small = cv2.resize(
                image, (max(1, image.shape[1] // 2), max(1, image.shape[0] // 2)), interpolation=cv2.INTER_AREA
            )
            cv2.imwrite(str(folder / str(level) / f"{r}_{c}.jpg"), small, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        heights = [max(1, sum(heights[k : k + 2]) // 2) for k in range(0, len(heights), 2)]
        widths = [max(1, sum(widths[k : k + 2]) // 2) for k in range(0, len(widths), 2)]
    return levels


def page_data(
    graph: BoundaryGraph, mosaic: Mosaic, levels: int, ground_truth=(), boundaries: list[dict] | None = None
) -> dict:
    """What the page draws, in mosaic pixels: vertices, edges (polyline, score, kind), the
    boundaries a reviewer acts on (``boundaries``: each one's ``edges`` in walk order, ``score``,
    ``draft`` and ``length_m``; by default the graph's chains, all in the draft) and the ground
    truth; plus the mosaic's transform to send edits back in world coordinates."""

    def to_mosaic(points_px: np.ndarray) -> np.ndarray:
        xs, ys = pixel_to_world(graph.transform, points_px[:, 0], points_px[:, 1])
        cols, rows = world_to_pixel(mosaic.transform, np.asarray(xs), np.asarray(ys))
        return np.stack([cols, rows], axis=1)

    vertices = to_mosaic(graph.vertices) if graph.n_vertices else np.zeros((0, 2))
    edges = []
    for k, (u, v) in enumerate(graph.edges):
        line = graph.edge_polyline(k)
        score = (
            float(graph.edge_scores[k]) if graph.edge_scores is not None and np.isfinite(graph.edge_scores[k]) else None
        )
        edges.append(
            {
                "id": k,
                "u": int(u),
                "v": int(v),
                "line": np.round(to_mosaic(np.asarray(line, float)), 2).tolist(),
                "score": score,
                "kind": graph.edge_kinds[k] if graph.edge_kinds is not None else "normal",
            }
        )
    gt = []
    for line in ground_truth:
        xy = np.asarray(line.coords)[:, :2]
        cols, rows = world_to_pixel(mosaic.transform, xy[:, 0], xy[:, 1])
        gt.append(np.round(np.stack([cols, rows], axis=1), 2).tolist())
    if boundaries is None:
        boundaries = [
            {
                "edges": b.edges.tolist(),
                "score": b.confidence if np.isfinite(b.confidence) else None,
                "draft": True,
                "length_m": None,
            }
            for b in graph_boundaries(graph)
        ]
    return {
        "width": mosaic.width,
        "height": mosaic.height,
        "tile": TILE,
        "levels": levels,
        "crs": graph.crs,
        "transform": list(mosaic.transform)[:6],
        "vertices": np.round(vertices, 3).tolist(),
        "edges": edges,
        "boundaries": boundaries,
        "ground_truth": gt,
    }


def write_review_page(
    graph: BoundaryGraph,
    mosaic: Mosaic,
    out: str | Path,
    ground_truth=(),
    progress: bool = True,
    fingerprint: str | None = None,
    ids: tuple[np.ndarray, np.ndarray] | None = None,
    review_costs: dict | None = None,
    boundaries: list[dict] | None = None,
    metres_per_px: float | None = None,
) -> Path:
    """The review folder ``out`` (``index.html``, ``data.js``, the scripts, ``tiles/``);
    ``fingerprint`` (of the graph's file) goes into every edits file the page exports. ``ids``
    (edge numbers, vertex numbers) are those of a district's edges and vertices in the whole
    graph: the exported edits name those. ``review_costs`` (seconds per look and per deletion,
    :class:`csboundary.metrics.review_time.ReviewCosts`) price the minutes left the page shows;
    ``boundaries`` are what the reviewer acts on (:func:`page_data`), ``metres_per_px`` the graph's
    pixel size (a boundary cut on the page gets its length from it)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tiles = out / "tiles"
    if tiles.exists():
        shutil.rmtree(tiles)
    levels = write_pyramid(mosaic, tiles, progress)
    data = page_data(graph, mosaic, levels, ground_truth, boundaries)
    data["metres_per_px"] = metres_per_px
    data["graph_sha256"] = fingerprint
    data["review_costs"] = review_costs
    if ids is not None:
        data["edge_ids"], data["vertex_ids"] = (np.asarray(i).tolist() for i in ids)
    with atomic_path(out / "data.js") as tmp:
        tmp.write_text("window.REVIEW_DATA = " + json.dumps(data, separators=(",", ":")) + ";\n")
    static = resources.files("csboundary") / "viz" / "static"
    for name in STATIC:
        target = out / ("index.html" if name == "review.html" else name)
        with atomic_path(target) as tmp:
            tmp.write_text((static / name).read_text())
    return out / "index.html"
