"""Predict every patch of a city on its own and keep each patch's core: the patch-scale result.

This is how the paper's patch-scale numbers are made (each 1000 px patch judged on its own
prediction). The union of the cores is also the "no stitching" city graph: boundaries are cut
at every core edge, which city-scale stitching (paper IV-E) repairs.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString
from tqdm import tqdm

from csboundary.data.grid import PatchGrid
from csboundary.data.raster import Mosaic
from csboundary.graph import BoundaryGraph
from csboundary.pipeline.patch import PatchPredictor


def score_patchwise(predictor: PatchPredictor, mosaic: Mosaic, ground_truth, seed: int = 0, progress: bool = True) -> tuple[BoundaryGraph, dict, PatchGrid]:
    """Predict every patch on its own and score the result against ``ground_truth`` (world
    LineStrings) at patch scale; returns the prediction, the scores and the grid."""
    from csboundary.metrics import evaluate

    grid = PatchGrid.for_mosaic(mosaic)
    pred = predict_patchwise(predictor, mosaic, grid, progress)
    gt = BoundaryGraph.from_world_lines(list(ground_truth), mosaic.transform)
    return pred, evaluate(pred, gt, scale="patch", grid=grid, seed=seed), grid


def predict_patchwise(predictor: PatchPredictor, mosaic: Mosaic, grid: PatchGrid, progress: bool = True) -> BoundaryGraph:
    """One graph in mosaic pixels: each patch's predicted edges clipped to that patch's core."""
    lines: list[np.ndarray] = []
    for patch in tqdm(list(grid), desc="predict patches", unit="patch", disable=not progress):
        read = mosaic.read(patch.expanded)
        graph = predictor.graph(read.data)
        offset = np.array([patch.expanded.col_off, patch.expanded.row_off], float)
        core = patch.core
        for line in graph.to_linestrings():
            moved = LineString(np.asarray(line.coords) + offset)
            clipped = shapely.clip_by_rect(moved, core.col_off, core.row_off, core.col_end, core.row_end)
            for part in getattr(clipped, "geoms", [clipped]):
                if part.geom_type == "LineString" and part.length > 0:
                    lines.append(np.asarray(part.coords))
    return BoundaryGraph.from_polylines(lines, transform=mosaic.transform, crs=mosaic.crs.to_string() if mosaic.crs else None)
