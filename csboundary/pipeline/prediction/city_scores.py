"""A predicted city scored against its ground truth: a run's result at the paper's two scales, and
the labelled city directories of a set predicted as ``predict`` reads them and scored."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

from csboundary.data import city_layout
from csboundary.data.inputs import open_imagery
from csboundary.data.model_view import model_view
from csboundary.errors import InputError, InputWarning
from csboundary.labels.mask_import import SET_FILE
from csboundary.models.patch_model import PatchModel
from csboundary.pipeline.prediction.city import patch_scale_graph, predict_city
from csboundary.pipeline.prediction.city_job import CityResult
from csboundary.pipeline.prediction.options import PredictionOptions


def evaluate_run(
    result: CityResult,
    ground_truth,
    seed: int = 0,
    scales: tuple[str, ...] = ("patch", "city"),
    metres_per_px: float | None = None,
) -> dict[str, dict]:
    """Scores against ``ground_truth`` (world LineStrings) at the paper's two scales, those in
    ``scales``: ``patch`` (each patch's own graph on its core, averaged; Table I) and ``city``
    (the stitched graph as a whole; Table II). ``metres_per_px`` (the frame's pixel size) puts
    the city scale's review effort per km."""
    from csboundary.graph import BoundaryGraph
    from csboundary.metrics import evaluate

    gt = BoundaryGraph.from_world_lines(list(ground_truth), result.grid.transform)
    score = {
        "patch": lambda: evaluate(patch_scale_graph(result), gt, scale="patch", grid=result.grid, seed=seed),
        "city": lambda: evaluate(
            result.graph,
            gt,
            scale="city",
            seed=seed,
            extent=(0, 0, result.grid.width, result.grid.height),
            metres_per_px=metres_per_px,
        ),
    }
    return {scale: score[scale]() for scale in scales}


def set_cities(set_dir: str | Path) -> list[Path]:
    """The city directories of a set: those ``set.json`` lists, else every city directory inside."""
    set_dir = Path(set_dir)
    if not set_dir.is_dir():
        raise InputError(set_dir, "not a folder")
    listing = set_dir / SET_FILE
    if listing.exists():
        try:
            names = [c["dir"] for c in json.loads(listing.read_text())["cities"]]
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            raise InputError(listing, f"not a set listing ({exc})") from exc
        cities = [set_dir / n for n in names]
    else:
        cities = sorted(p for p in set_dir.iterdir() if city_layout.is_city_dir(p))
    missing = [c for c in cities if not city_layout.is_city_dir(c)]
    if missing:
        raise InputError(missing[0], "listed in the set but not a city directory")
    if not cities:
        raise InputError(set_dir, "holds no city directory (see csboundary import-masks)")
    return cities


def predicted_city(
    city_dir: str | Path,
    model: PatchModel,
    options: PredictionOptions = PredictionOptions(progress=False),
    *,
    assume_model_gsd: bool = False,
) -> tuple[CityResult, list]:
    """``model``'s prediction of a labelled city directory, read as ``predict`` reads it, and the
    city's ground-truth lines. ``assume_model_gsd``: imagery without a pixel size is taken to be
    at the model's (imported crops), and RGB is read without warnings (NIR := green is the
    documented rule); ``options``: how it is predicted (sweeps vary the stitching)."""
    city_layout.read_meta(city_dir)
    with warnings.catch_warnings():
        if assume_model_gsd:
            warnings.simplefilter("ignore", InputWarning)
        mosaic, lines = open_imagery([city_dir])
        view = model_view(mosaic, model_gsd=model.pixel_size_m, assume_model_gsd=assume_model_gsd)
    with view.mosaic:
        result = predict_city(view.mosaic, model, options)
    return result, lines


def evaluate_city_dir(city_dir: Path, model: PatchModel, seed: int = 0) -> dict[str, Any]:
    """City-scale scores of ``model`` on one city of a set (see :func:`predicted_city`)."""
    result, lines = predicted_city(city_dir, model, assume_model_gsd=True)
    scores = evaluate_run(result, lines, seed, scales=("city",), metres_per_px=model.pixel_size_m)["city"]
    scores["counts"] = {"pred_edges": int(result.graph.n_edges), "gt_lines": len(lines)}
    return scores


def evaluate_city(
    city_dir: str | Path, model: PatchModel, seed: int = 0, batch_size: int = 1, progress: bool = True
) -> dict[str, dict]:
    """Patch-scale (each patch's graph on its core) and city-scale (the stitched graph) scores of
    ``model`` on a city directory with ground truth, without writing the prediction."""
    result, lines = predicted_city(city_dir, model, PredictionOptions(batch_size=batch_size, progress=progress))
    scores = evaluate_run(result, lines, seed, metres_per_px=model.pixel_size_m)
    for item in scores.values():
        item["inputs"] = {"gt": str(city_layout.ground_truth_path(city_dir))}
    return scores


def score_value(value) -> float:
    """A city's score as a set counts it: undefined (None, NaN) is 0."""
    return 0.0 if value is None or (isinstance(value, float) and math.isnan(value)) else float(value)
