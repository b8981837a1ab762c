"""What a command's inputs name: a city directory (its tiles and ground truth), or raster files
and folders plus an optional ground-truth file. One reading for every command, so ``predict``,
``show`` and ``evaluate-model`` agree on what a path means."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from csboundary.data import city_layout
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic


def open_imagery(inputs: Sequence[str | Path], ground_truth: str | Path | None = None) -> tuple[Mosaic, list]:
    """The mosaic of ``inputs`` and the ground-truth lines (shapely, in the mosaic's CRS; empty
    without ground truth). A single city directory gives its tiles and, unless ``ground_truth``
    is given, its own ground truth. Raises InputError naming a file that cannot be read."""
    inputs = [Path(p) for p in inputs]
    looks_like_city = len(inputs) == 1 and (
        city_layout.tiles_dir(inputs[0]).is_dir() or city_layout.ground_truth_path(inputs[0]).exists()
    )
    if looks_like_city:
        city_layout.read_meta(inputs[0])  # a city without a readable city.json is an interrupted write, not input
    if len(inputs) == 1 and city_layout.is_city_dir(inputs[0]):
        mosaic = Mosaic.open(city_layout.tiles_dir(inputs[0]))
        if ground_truth is None and city_layout.ground_truth_path(inputs[0]).exists():
            ground_truth = city_layout.ground_truth_path(inputs[0])
    else:
        mosaic = Mosaic.open(inputs)
    lines = []
    if ground_truth is not None:
        lines = list(read_ground_truth(ground_truth, mosaic.crs).geometry)
    return mosaic, lines
