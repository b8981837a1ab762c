"""A city directory from a user's own GeoTIFF tiles and vector road boundaries.

The training, evaluation and benchmark commands read cities (:mod:`csboundary.data.city_layout`). A
user with labelled imagery of their own (tiles plus curbs digitised in a GIS) gets one with
``csboundary make-city``: the tiles are checked as one mosaic (same CRS, pixel size, grid) and
linked, not copied (a city's imagery can be gigabytes), and the boundaries are reprojected into
the tiles' CRS and written as the city's ground truth.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from shapely.geometry import box

from csboundary.data.city_layout import begin_city, ground_truth_path, tiles_dir, write_meta
from csboundary.data.ground_truth import read_ground_truth, write_ground_truth
from csboundary.data.model_view import mosaic_units
from csboundary.data.raster import Mosaic
from csboundary.data.units import MODEL_GSD, geometric_mean, pixel_size_m
from csboundary.data.windows import pixel_to_world
from csboundary.errors import InputError, InputWarning

SOURCE = "user"


def make_city(tiles: list[str | Path], ground_truth: str | Path, out: str | Path, complete=None) -> dict[str, Any]:
    """Check ``tiles`` and ``ground_truth``, then write the city ``out`` (tiles linked); returns its
    metadata. ``complete``: a GeoDataFrame of the polygons where the boundaries are complete
    (labels elsewhere are unknown); None: complete everywhere. With ``complete``, ground truth
    without a single boundary is a label too: every pixel inside the areas is a negative."""
    with Mosaic.open(tiles) as mosaic:
        paths = [Path(t.path).resolve() for t in mosaic.tiles]
        crs = mosaic.crs
        gsd = abs(mosaic.transform.a)  # CRS units (feet, degrees...): only for city.json's gsd
        units = mosaic_units(mosaic)
        pixel_m = geometric_mean(pixel_size_m(units, mosaic.transform)) if units is not None else None
        size = (mosaic.width, mosaic.height)
        xs, ys = pixel_to_world(mosaic.transform, np.array([0.0, size[0]]), np.array([0.0, size[1]]))
    if crs is None:
        raise InputError(paths[0], "has no CRS: the ground truth cannot be placed on it")
    names = [p.name for p in paths]
    if len(set(names)) != len(names):
        duplicate = next(n for n in names if names.count(n) > 1)
        raise InputError(duplicate, "two tiles share this file name; rename one")
    frame = read_ground_truth(ground_truth, crs)
    if frame.crs is None:
        raise InputError(ground_truth, "has no CRS: cannot tell whether it matches the tiles")
    if len(frame) == 0 and complete is None:  # nothing to learn from: no boundary, and no area said to have none
        raise InputError(ground_truth, "holds no road boundaries")
    # none inside a complete area is a label ("no curb here"); some, all off the tiles, is a wrong CRS
    if len(frame) and not frame.intersects(box(xs.min(), ys.min(), xs.max(), ys.max())).any():
        raise InputError(ground_truth, f"no boundary lies on the tiles (checked in {crs}); is its CRS right?")
    if abs(pixel_m / MODEL_GSD - 1) > 0.15:
        warnings.warn(
            f"{paths[0]}: pixel size {pixel_m:.3g} m differs from the model's {MODEL_GSD:g} m; resample the tiles "
            "(e.g. gdalwarp -tr) so training sees objects at the size it predicts them",
            InputWarning,
            stacklevel=2,
        )
    out = begin_city(out)
    folder = tiles_dir(out)
    folder.mkdir(parents=True, exist_ok=True)
    for path in paths:
        os.symlink(path, folder / path.name)
    if complete is not None:
        complete = complete.to_crs(crs) if complete.crs is not None else complete.set_crs(crs)
    write_ground_truth(ground_truth_path(out), frame, complete=complete)
    meta = {
        "source": SOURCE,
        "crs": crs.to_string(),
        "gsd": gsd,
        "units": units.unit_name,
        "pixel_m": pixel_m,
        "width": size[0],
        "height": size[1],
        "tiles": names,
        "tile_sources": [str(p) for p in paths],
        "ground_truth_source": str(Path(ground_truth).resolve()),
        "boundaries": len(frame),
        **({"complete_areas": len(complete)} if complete is not None else {}),
        "notes": "Tiles are symbolic links to the user's files; ground truth reprojected to the tiles' CRS.",
    }
    write_meta(out, meta)
    return meta
