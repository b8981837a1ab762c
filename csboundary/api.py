"""The Python API: what the main commands do, as functions (docs/api.md).

Each function is the library call behind a command, with the command's defaults: ``load_model``
(the weights and graph settings every prediction takes), ``predict`` (``csboundary predict``),
``predict_patch`` (``predict-patch``), ``evaluate`` (``evaluate``: two graph files),
``evaluate_model`` and ``evaluate_set`` (``evaluate-model``, ``evaluate-set``), ``finetune`` and
``adapt`` (the commands of the same names) and ``read_prediction`` (a prediction folder or file
back as a :class:`~csboundary.graph.BoundaryGraph`). Bad input raises
:class:`~csboundary.errors.InputError`, whose message is the command line's ``error:`` line.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Sequence

import csboundary
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.settings import GraphOverrides as GraphOverrides
from csboundary.graph.settings import GraphSettings as GraphSettings
from csboundary.pipeline.prediction.options import PredictionOptions as PredictionOptions
from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor

__all__ = csboundary.__all__  # the API's names, listed once (csboundary/__init__.py)


def load_model(
    weights: str | Path | None = None,
    *,
    device: str = "auto",
    engine: str = "auto",
    precision: str = "auto",
    graph: GraphOverrides = GraphOverrides(),
) -> PatchPredictor:
    """The networks of a weights bundle (default: the shipped one) with its graph settings, and
    ``graph`` over them (the command line's graph options); ``device`` auto|cpu|cuda, ``engine``
    auto|torch|onnx, ``precision`` auto|float32|bfloat16|int8, as the commands take them. Its
    ``settings`` (a frozen :class:`GraphSettings`) say what every prediction with it does."""
    return load_predictor(weights, device, graph, engine=engine, precision=precision)


def predict(
    imagery: str | Path | Sequence[str | Path],
    out: str | Path,
    model: PatchPredictor | None = None,
    options: PredictionOptions | None = None,
    **changes,
) -> dict:
    """Predict a city (GeoTIFF tiles, a folder of them or a city folder) into the folder ``out``
    and return its ``summary.json``; ``model`` defaults to :func:`load_model`. ``options`` (a
    :class:`PredictionOptions`; default: the command's, without progress bars) say how, and
    ``changes`` replace some of them by name (``gsd``, ``batch_size``, ``write_maps``,
    ``lanelet2``, ``restart``, ``workers``, ...). A run stopped part-way is continued by the same
    call."""
    from csboundary.pipeline.jobs.predict import predict_to_folder

    inputs = [imagery] if isinstance(imagery, (str, Path)) else list(imagery)
    options = dataclasses.replace(options or PredictionOptions(progress=False), **changes)
    return predict_to_folder(inputs, out, _model(model), options)


def predict_patch(
    image: str | Path, out: str | Path, model: PatchPredictor | None = None, *, gsd: float | None = None
) -> BoundaryGraph:
    """The graph of one image of at most 1100 x 1100 px at the model's pixel size, as ``predict``
    would make it, written into ``out`` (graph.json, boundaries.geojson, overlay.png)."""
    from csboundary.pipeline.jobs.predict import predict_patch_to_folder

    return predict_patch_to_folder(image, out, _model(model), gsd)


def _model(model) -> PatchPredictor:
    """``model``, or :func:`load_model`'s default when None; anything else (a path or a name given
    where a loaded model belongs) is one line saying what to do."""
    if model is None:
        return load_model()
    if not isinstance(model, PatchPredictor):
        raise InputError(
            str(model)[:80], "is not a loaded model: give csboundary.load_model(WEIGHTS), or leave model out"
        )
    return model


def evaluate(prediction: str | Path, ground_truth: str | Path, *, seed: int = 0, gsd: float | None = None) -> dict:
    """Relaxed precision, recall and F1 at 2, 5 and 10 px, APLS, TLTS (and, with scores, the
    confidence; the simulated review) of a prediction against ground truth: graph.json,
    GeoPackage or GeoJSON files, or a city folder for either (docs/metrics.md)."""
    from csboundary.metrics import evaluate as scores
    from csboundary.metrics.io import frame_metres_per_px, load_pair

    pred, truth, frame = load_pair(prediction, ground_truth, gsd=gsd)
    extent = (0, 0, frame.width, frame.height) if frame.width else None  # the imagery's rectangle, where one is known
    return scores(pred, truth, seed=seed, extent=extent, metres_per_px=frame_metres_per_px(frame))


def evaluate_model(
    city: str | Path, model: PatchPredictor | None = None, *, seed: int = 0, progress: bool = False
) -> dict:
    """A model's scores on a labelled city, at patch and city scale (``evaluate-model``)."""
    from csboundary.pipeline.prediction.city_scores import evaluate_city

    return evaluate_city(city, model or load_model(), seed, progress=progress)


def evaluate_set(
    folder: str | Path, model: PatchPredictor | None = None, *, seed: int = 0, progress: bool = False
) -> dict:
    """A model's city-scale scores on every labelled city of ``folder``, and their mean."""
    from csboundary.pipeline.evaluation.evaluate_set import evaluate_set as scores

    return scores(folder, model or load_model(), seed=seed, progress=progress)


def finetune(labelled: Sequence[str | Path], out: str | Path, **options) -> dict:
    """Fine-tune the weights on labelled cities or reviewed predictions into the bundle ``out``;
    ``options`` are :func:`csboundary.pipeline.training.finetune.finetune`'s (``weights``,
    ``budget``, ``seed``, ``device``, ...)."""
    from csboundary.pipeline.training.finetune import finetune as tune

    return tune([Path(p) for p in labelled], Path(out), **options)


def adapt(imagery: Sequence[str | Path], out: str | Path, **options) -> dict:
    """Adapt the weights to a city from its unlabelled imagery into the bundle ``out``;
    ``options`` are :func:`csboundary.pipeline.training.adapt.adapt`'s."""
    from csboundary.pipeline.training.adapt import adapt as self_train

    return self_train([Path(p) for p in imagery], Path(out), **options)


def read_prediction(source: str | Path) -> BoundaryGraph:
    """A prediction (its folder, graph.json or boundaries.gpkg) as a graph in its CRS."""
    from csboundary.pipeline.outputs.prediction_reader import read_prediction_graph

    return read_prediction_graph(source)
