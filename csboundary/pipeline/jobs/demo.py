"""The main job on an embedded default: a small synthetic test city, predicted with the shipped
weights exactly as ``predict`` does and scored against its ground truth (``csboundary demo``)."""

from __future__ import annotations

from pathlib import Path

from csboundary.data.atomic import check_output_dir
from csboundary.data.inputs import open_imagery
from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig
from csboundary.metrics.report import write_scores
from csboundary.pipeline.jobs.predict import model_settings
from csboundary.pipeline.jobs.prediction_run import run_prediction
from csboundary.pipeline.prediction.city_scores import evaluate_run
from csboundary.pipeline.prediction.patch import PatchPredictor

TILES = (2, 2)  # 2x2 tiles of 1500 px: a 3000 px city, 3x3 patches
TILE_SIZE = 1500


def run_demo(out: str | Path, predictor: PatchPredictor, seed: int = 0) -> dict:
    """Synthesize the test-split city ``seed`` into OUT/city, predict it into OUT/prediction,
    score it at patch and city scale into OUT/scores.json; returns the city's metadata
    (``meta``), the run's ``summary``, the ``scores`` and the city's size in px (``size``)."""
    out = check_output_dir(out)
    city_dir = out / "city"
    meta = synthesize_city(city_dir, seed, "test", TILES, SynthConfig(tile_size=TILE_SIZE))
    mosaic, lines = open_imagery([city_dir])
    settings = model_settings(predictor)
    with mosaic:
        result, summary = run_prediction(mosaic, predictor, out / "prediction", settings=settings, ground_truth=lines)
    scores = evaluate_run(result, lines, seed=0)
    for item in scores.values():
        item["inputs"] = {"pred": str(out / "prediction"), "gt": str(city_dir / "ground_truth.gpkg")}
    write_scores(out / "scores.json", scores)
    return {"meta": meta, "summary": summary, "scores": scores, "size": (mosaic.width, mosaic.height)}
