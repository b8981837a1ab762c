"""Write every patch's labels of a city: compressed arrays plus the patch graph as JSON.

::

    OUT/labels.json                 config, grid, city, counts, timings (written last)
    OUT/patches/rRR_cCC.npz         segmentation, orientation (int8 x127), orientation_bins,
                                    keypoint_heat (uint8 x255), valid (image pixels present)
    OUT/patches/rRR_cCC.graph.json  the patch's ground-truth graph (csboundary-graph JSON)
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from csboundary.data import city_layout
from csboundary.data.atomic import atomic_path
from csboundary.data.grid import Patch, PatchGrid
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.labels.boundaries import Boundary, boundaries_from_world
from csboundary.labels.config import LabelConfig
from csboundary.labels.keypoints import BoundaryKeypoints, compute_keypoints
from csboundary.labels.patch_graph import patch_graph
from csboundary.labels.rasterize import keypoint_heat, orientation_label, segmentation_label
from csboundary.labels.select import boundary_bounds

MANIFEST = "labels.json"
PATCH_DIR = "patches"


@dataclass
class CityLabels:
    """Global label geometry of a city: boundaries and keypoints in mosaic pixels, and the grid."""

    boundaries: list[Boundary]
    keypoints: list[BoundaryKeypoints]
    bounds: np.ndarray
    grid: PatchGrid
    crs: str | None
    config: LabelConfig

    @classmethod
    def build(cls, lines, mosaic: Mosaic, config: LabelConfig = LabelConfig()) -> "CityLabels":
        boundaries = boundaries_from_world(lines, mosaic.transform)
        grid = PatchGrid.for_mosaic(mosaic, config.grid)
        crs = mosaic.crs.to_string() if mosaic.crs is not None else None
        return cls(boundaries, compute_keypoints(boundaries, config), boundary_bounds(boundaries), grid, crs, config)

    def patch_arrays(self, patch: Patch) -> dict[str, np.ndarray]:
        c = self.config
        window = patch.expanded
        vectors, codes = orientation_label(
            self.boundaries, self.bounds, window, c.segmentation_width, c.orientation_bins
        )
        return {
            "segmentation": segmentation_label(self.boundaries, self.bounds, window, c.segmentation_width),
            "orientation": vectors,
            "orientation_bins": codes,
            "keypoint_heat": keypoint_heat(self.keypoints, self.bounds, window, c.heat_sigma_px),
        }

    def network_targets(self, window) -> np.ndarray:
        """(2, h, w) float32 keypoint heat and segmentation of a window: what the FPN learns to
        predict (and what the ground-truth oracle feeds the pipeline in its place)."""
        c = self.config
        heat = keypoint_heat(self.keypoints, self.bounds, window, c.heat_sigma_px)
        seg = segmentation_label(self.boundaries, self.bounds, window, c.segmentation_width)
        return np.stack([heat, seg.astype(np.float32)]).astype(np.float32)

    def patch_graph(self, patch: Patch) -> BoundaryGraph:
        return patch_graph(self.keypoints, self.bounds, patch, self.crs)


def patch_stem(patch: Patch) -> str:
    return f"r{patch.row:02d}_c{patch.col:02d}"


def save_patch_arrays(path: Path, arrays: dict[str, np.ndarray], valid: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(
                fh,
                segmentation=arrays["segmentation"].astype(np.uint8),
                orientation=np.round(arrays["orientation"] * 127).astype(np.int8),
                orientation_bins=arrays["orientation_bins"],
                keypoint_heat=np.round(arrays["keypoint_heat"] * 255).astype(np.uint8),
                valid=valid.astype(np.uint8),
            )


def load_patch_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """Inverse of :func:`save_patch_arrays`: floats back in [0, 1] / unit vectors."""
    try:
        with np.load(path) as data:
            return {
                "segmentation": data["segmentation"],
                "orientation": data["orientation"].astype(np.float32) / 127.0,
                "orientation_bins": data["orientation_bins"],
                "keypoint_heat": data["keypoint_heat"].astype(np.float32) / 255.0,
                "valid": data["valid"].astype(bool),
            }
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(path, f"not a patch label file ({exc})") from exc


def write_city_labels(
    city_dir: str | Path, out_dir: str | Path, config: LabelConfig = LabelConfig(), progress: bool = True
) -> dict:
    """Compute and write the labels of every patch of ``city_dir``; returns the manifest."""
    city_dir, out_dir = Path(city_dir), Path(out_dir)
    city_layout.read_meta(city_dir)  # fails clearly if this is not a city
    (out_dir / MANIFEST).unlink(missing_ok=True)
    start = time.perf_counter()
    with Mosaic.open(city_layout.tiles_dir(city_dir)) as mosaic:
        gt = read_ground_truth(city_layout.ground_truth_path(city_dir), mosaic.crs)
        labels = CityLabels.build(list(gt.geometry), mosaic, config)
        prepared = time.perf_counter() - start
        counts = {"patches": 0, "vertices": 0, "edges": 0, "corner_edges": 0}
        for patch in tqdm(list(labels.grid), desc="patch labels", unit="patch", disable=not progress):
            stem = patch_stem(patch)
            valid = mosaic.read(patch.expanded).valid
            save_patch_arrays(out_dir / PATCH_DIR / f"{stem}.npz", labels.patch_arrays(patch), valid)
            graph = labels.patch_graph(patch)
            graph.write_json(out_dir / PATCH_DIR / f"{stem}.graph.json")
            counts["patches"] += 1
            counts["vertices"] += graph.n_vertices
            counts["edges"] += graph.n_edges
            counts["corner_edges"] += sum(k == "corner" for k in graph.edge_kinds or [])
    manifest = {
        "city": str(city_dir.resolve()),
        "config": config.to_dict(),
        "grid": [labels.grid.n_rows, labels.grid.n_cols],
        "mosaic": [mosaic.width, mosaic.height],
        "crs": labels.crs,
        "counts": counts,
        "seconds": {"prepare": round(prepared, 2), "total": round(time.perf_counter() - start, 2)},
    }
    with atomic_path(out_dir / MANIFEST) as tmp:
        tmp.write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest
