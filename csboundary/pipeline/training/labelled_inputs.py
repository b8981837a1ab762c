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

from csboundary.data import city_layout
from csboundary.data.ground_truth import LAYER, read_complete_area
from csboundary.data.raster import Mosaic
from csboundary.data.user_city import make_city
from csboundary.errors import InputError
from csboundary.labels.mask_import import SET_FILE
from csboundary.models.training.data import covers_imagery
from csboundary.pipeline.outputs.review import REVIEW_LOG, prediction_inputs
from csboundary.pipeline.outputs.review_apply import read_log
from csboundary.pipeline.prediction.city_scores import set_cities

REVIEWED_GROUND_TRUTH = "boundaries.gpkg"  # the prediction's GeoPackage, rewritten by apply-review


def complete_areas(prediction: Path) -> list[list[list[float]]]:
    """Every area marked complete in the prediction's review log (rings in its CRS)."""
    log = read_log(prediction / REVIEW_LOG)
    return [ring for entry in log["reviews"] for ring in entry.get("complete_areas") or []]


def reviewed_areas(prediction: Path) -> gpd.GeoDataFrame:
    """The areas marked complete in a reviewed prediction folder, checked to cover some of its
    imagery; InputError when none is marked (nothing in it is known to be a label) or none
    covers the imagery (apply-review checks it; a review log edited by other means may not)."""
    areas = complete_areas(prediction)
    if not areas:
        raise InputError(
            prediction,
            "no area of it is marked complete: on the review page mark what you reviewed "
            "(Area, or View complete), export the edits and run apply-review",
        )
    crs = pyogrio.read_info(prediction / REVIEWED_GROUND_TRUTH, layer=LAYER)[
        "crs"
    ]  # the graph's, in which the areas were drawn
    complete = gpd.GeoDataFrame(geometry=[Polygon(ring) for ring in areas], crs=crs)
    with Mosaic.open(prediction_inputs(prediction)) as mosaic:
        if not covers_imagery(list(complete.to_crs(mosaic.crs).geometry if mosaic.crs else complete.geometry), mosaic):
            raise InputError(
                prediction / REVIEW_LOG,
                "no area marked complete in it covers any of the imagery (they lie in "
                "the margin around it): mark the areas again and run apply-review",
            )
    return complete


def reviewed_city(prediction: Path, out: Path, complete: gpd.GeoDataFrame) -> Path:
    """The city directory ``out`` of a reviewed prediction folder: its imagery (linked), its
    reviewed boundaries as ground truth and its ``complete`` areas (:func:`reviewed_areas`)."""
    make_city(prediction_inputs(prediction), prediction / REVIEWED_GROUND_TRUTH, out, complete=complete)
    return out


def check_complete_area(city: Path) -> None:
    """A labelled city with a complete area must have some of its imagery inside it."""
    with Mosaic.open(city_layout.tiles_dir(city)) as mosaic:
        areas = read_complete_area(city_layout.ground_truth_path(city), mosaic.crs)
        if areas is not None and not covers_imagery(areas, mosaic):
            raise InputError(city, "its complete area does not cover any of its imagery")


def is_reviewed_prediction(path: Path) -> bool:
    return (path / "summary.json").exists() and (path / REVIEW_LOG).exists()


def labelled_cities(paths: list[Path], work: Path) -> list[Path]:
    """The city directories of ``paths``: a city is itself, a set (``set.json``, or a folder of
    cities) is its cities, a reviewed prediction becomes a city under ``work/labelled/``. Every
    input is checked before anything is made in ``work``: a refused one leaves nothing behind."""
    found: list[Path] = []
    reviewed: dict[Path, tuple[Path, gpd.GeoDataFrame]] = {}  # city to make -> (prediction, its complete areas)
    for path in paths:
        path = Path(path)
        if city_layout.is_city_dir(path):
            found.append(path)
        elif is_reviewed_prediction(path):
            digest = hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:8]
            found.append(work / "labelled" / f"{path.name}-{digest}")
            reviewed[found[-1]] = (path, reviewed_areas(path))
        elif (path / SET_FILE).exists() or (path.is_dir() and any(city_layout.is_city_dir(p) for p in path.iterdir())):
            found += set_cities(path)
        elif (path / "summary.json").exists():
            raise InputError(
                path,
                "a prediction that was never reviewed: review it (csboundary review), mark the complete "
                "area and apply-review, or give a labelled city",
            )
        else:
            raise InputError(path, "not a labelled city, a set of them, or a reviewed prediction folder")
    names = [p.resolve() for p in found]
    if len(set(names)) != len(names):
        raise InputError(next(p for p in found if names.count(p.resolve()) > 1), "given twice")
    for city in found:
        if city not in reviewed:
            check_complete_area(city)
    for city, (prediction, complete) in reviewed.items():
        reviewed_city(prediction, city, complete)
    return found
