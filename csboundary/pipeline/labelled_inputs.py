"""What a user can fine-tune on, as city directories: labelled cities (``make-city``,
``import-masks``, ``synth``), sets of them, and reviewed prediction folders.

A reviewed prediction is labelled only where the reviewer marked an area complete on the review
page (``apply-review`` records the areas in ``review.json``). It becomes a city whose tiles are
links to the prediction's imagery, whose ground truth is the reviewed graph, and whose
``complete_area`` layer holds those areas: training reads labels there and treats the rest as
unknown, not as background.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import geopandas as gpd
import pyogrio
from shapely.geometry import Polygon

from csboundary.data import city as layout
from csboundary.data.ground_truth import LAYER
from csboundary.data.user_city import make_city
from csboundary.errors import InputError
from csboundary.labels.mask_import import SET_FILE
from csboundary.pipeline.evaluate_set import set_cities
from csboundary.pipeline.review import REVIEW_LOG, prediction_inputs, read_log

REVIEWED_GROUND_TRUTH = "boundaries.gpkg"  # the prediction's GeoPackage, rewritten by apply-review


def complete_areas(prediction: Path) -> list[list[list[float]]]:
    """Every area marked complete in the prediction's review log (rings in its CRS)."""
    log = read_log(prediction / REVIEW_LOG)
    return [ring for entry in log["reviews"] for ring in entry.get("complete_areas") or []]


def reviewed_city(prediction: Path, out: Path) -> Path:
    """The city directory ``out`` of a reviewed prediction folder: its imagery (linked), its
    reviewed boundaries as ground truth and its complete areas; InputError when no area is
    marked complete (nothing in it is known to be a label)."""
    areas = complete_areas(prediction)
    if not areas:
        raise InputError(prediction, "no area of it is marked complete: on the review page mark what you reviewed "
                                     "(Area, or View complete), export the edits and run apply-review")
    ground_truth = prediction / REVIEWED_GROUND_TRUTH
    crs = pyogrio.read_info(ground_truth, layer=LAYER)["crs"]  # the graph's, in which the areas were drawn
    complete = gpd.GeoDataFrame(geometry=[Polygon(ring) for ring in areas], crs=crs)
    make_city(prediction_inputs(prediction), ground_truth, out, complete=complete)
    return out


def is_reviewed_prediction(path: Path) -> bool:
    return (path / "summary.json").exists() and (path / REVIEW_LOG).exists()


def labelled_cities(paths: list[Path], work: Path) -> list[Path]:
    """The city directories of ``paths``: a city is itself, a set (``set.json``, or a folder of
    cities) is its cities, a reviewed prediction becomes a city under ``work/labelled/``."""
    found: list[Path] = []
    for path in paths:
        path = Path(path)
        if layout.is_city_dir(path):
            found.append(path)
        elif is_reviewed_prediction(path):
            digest = hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:8]
            found.append(reviewed_city(path, work / "labelled" / f"{path.name}-{digest}"))
        elif (path / SET_FILE).exists() or (path.is_dir() and any(layout.is_city_dir(p) for p in path.iterdir())):
            found += set_cities(path)
        elif (path / "summary.json").exists():
            raise InputError(path, "a prediction that was never reviewed: review it (csboundary review), mark the complete "
                                   "area and apply-review, or give a labelled city")
        else:
            raise InputError(path, "not a labelled city, a set of them, or a reviewed prediction folder")
    names = [p.resolve() for p in found]
    if len(set(names)) != len(names):
        raise InputError(next(p for p in found if names.count(p.resolve()) > 1), "given twice")
    return found
