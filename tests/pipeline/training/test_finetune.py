"""Fine-tuning on a user's labels: a reviewed prediction becomes a city labelled only inside its
complete area (outside, the loss ignores every pixel and AfANet every vertex); the sampling share
of user cities; folds; and one tiny fine-tune run end to end, resumed without training again."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from shapely.geometry import box

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.styles import style_config
from csboundary.data.windows import PixelWindow, pixel_to_world
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.metrics.compare import paired_bootstrap
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.data import TrainingCity, city_probabilities
from csboundary.models.training.fpn import fpn_loss
from csboundary.pipeline.evaluation.finetune_cv import folds_of
from csboundary.pipeline.outputs.prediction_files import write_graph_outputs
from csboundary.pipeline.outputs.review_apply import apply_review
from csboundary.pipeline.training.labelled_inputs import labelled_cities

SIZE = 600


@pytest.fixture(scope="module")
def city(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("finetune") / "city"
    synthesize_city(out, seed=3, split="valid", config=style_config("classic", tile_size=SIZE), progress=False)
    return out


def _prediction(city: Path, folder: Path) -> tuple[Path, object]:
    """A prediction folder of ``city`` as predict leaves it: two vertical boundaries, at column
    100 (left half) and column 500 (right half), and the summary that names the imagery."""
    from csboundary.data.raster import Mosaic

    tiles = sorted((city / "tiles").glob("*.tif"))
    with Mosaic.open(tiles) as mosaic:
        transform, crs = mosaic.transform, mosaic.crs.to_string()
    graph = BoundaryGraph(
        np.array([[100.0, 50.0], [100.0, 550.0], [500.0, 50.0], [500.0, 550.0]]),
        [[0, 1], [2, 3]],
        edge_scores=np.array([0.9, 0.8]),
        transform=transform,
        crs=crs,
    )
    folder.mkdir(parents=True)
    graph.write_json(folder / "graph.json")
    write_graph_outputs(graph, folder)
    (folder / "summary.json").write_text(
        json.dumps({"inputs": [str(t.resolve()) for t in tiles], "mosaic_px": [SIZE, SIZE]})
    )
    return folder, transform


def _complete_left_half(folder: Path, transform, tmp_path: Path) -> None:
    """The reviewer marks the left half (columns 0-300) complete and applies it."""
    xs, ys = pixel_to_world(transform, np.array([0.0, 300.0]), np.array([0.0, float(SIZE)]))
    ring = [[float(v) for v in p] for p in box(min(xs), min(ys), max(xs), max(ys)).exterior.coords]
    edits = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"action": "complete"},
                "geometry": {"type": "Polygon", "coordinates": [ring]},
            }
        ],
    }
    (tmp_path / "edits.geojson").write_text(json.dumps(edits))
    apply_review(folder, tmp_path / "edits.geojson")


def test_a_reviewed_prediction_is_labelled_only_inside_its_complete_area(city, tmp_path):
    folder, transform = _prediction(city, tmp_path / "pred")
    _complete_left_half(folder, transform, tmp_path)
    [reviewed] = labelled_cities([folder], tmp_path / "work")
    with TrainingCity(reviewed) as training:
        window = PixelWindow(0, 0, SIZE, SIZE)
        image, targets, valid = training.fpn_sample(window)
        assert valid[:, :300].all() and not valid[:, 300:].any()  # labels known left of column 300 only
        assert (
            targets[1, 300, 98:103].max() > 0.5 and targets[1, 300, 498:503].max() > 0.5
        )  # both boundaries are drawn ...
        # ... yet the one outside the area costs nothing: the loss is the same with it erased, or with any target there
        config = TrainConfig(model="fpn", worlds={"cities": 1})
        logits = torch.from_numpy(np.random.default_rng(0).normal(size=(1, 2, SIZE, SIZE)).astype(np.float32))
        loss = lambda t: float(fpn_loss(logits, torch.from_numpy(t[None]), torch.from_numpy(valid[None]), config))  # noqa: E731
        changed = targets.copy()
        changed[:, :, 300:] = 1 - changed[:, :, 300:]
        assert loss(changed) == pytest.approx(loss(targets), abs=1e-7)
        changed[:, :, :300] = 1 - changed[:, :, :300]
        assert loss(changed) != pytest.approx(loss(targets), abs=1e-3)  # inside, labels count
        assert training.labelled(np.array([[100.0, 300.0], [500.0, 300.0], [299.5, 10.0], [-5.0, 10.0]])).tolist() == [
            True,
            False,
            True,
            False,
        ]
        for seed in range(20):  # every training window is centred on the complete area
            w = training.random_window(np.random.default_rng(seed), 256)
            assert w.col_off + 128 < 300 + 8


def _world(transform, col: float, row: float) -> list[float]:
    return [float(v) for v in pixel_to_world(transform, col, row)]


def test_predictions_that_are_not_labels_are_refused(city, tmp_path):
    folder, transform = _prediction(city, tmp_path / "pred")
    with pytest.raises(InputError, match="never reviewed"):
        labelled_cities([folder], tmp_path / "work")
    (tmp_path / "edits.geojson").write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"action": "accept", "edge": 0},
                        "geometry": {
                            "type": "LineString",
                            "coordinates": [_world(transform, 100.0, 50.0), _world(transform, 100.0, 550.0)],
                        },
                    }
                ],
            }
        )
    )
    apply_review(folder, tmp_path / "edits.geojson")
    with pytest.raises(InputError, match="no area of it is marked complete"):
        labelled_cities([folder], tmp_path / "work")
    with pytest.raises(InputError, match="not a labelled city"):
        labelled_cities([tmp_path], tmp_path / "work")
    with pytest.raises(InputError, match="given twice"):
        labelled_cities([city, city], tmp_path / "work")


class _City:
    def __init__(self, side: int, path: str | None = None):
        from csboundary.data.windows import PixelWindow

        self.mosaic = type("M", (), {"width": side, "height": side, "footprint": [PixelWindow(0, 0, side, side)]})
        self.path = Path(path or f"city-{id(self)}")


def test_user_cities_get_their_share_of_samples():
    cities = [_City(10), _City(20), _City(10), _City(30)]  # the last two are the user's
    p = city_probabilities(cities, extra=2, extra_share=0.25, by_area=True)
    assert np.allclose(p, [0.75 * 100 / 500, 0.75 * 400 / 500, 0.25 * 100 / 1000, 0.25 * 900 / 1000])
    assert np.allclose(
        city_probabilities(cities, extra=2, extra_share=0.25, by_area=False), [0.375, 0.375, 0.125, 0.125]
    )
    assert np.allclose(
        city_probabilities(cities, extra=2, extra_share=0.0, by_area=True), np.array([100, 400, 100, 900]) / 1500
    )
    assert np.allclose(
        city_probabilities(cities[2:], extra=2, extra_share=0.25, by_area=False), [0.5, 0.5]
    )  # only user cities
    parts = [
        _City(10),
        _City(10, "user"),
        _City(20, "user"),
        _City(30, "other"),
    ]  # the user city's scattered tiles: two parts
    assert np.allclose(
        city_probabilities(parts, extra=3, extra_share=0.5, by_area=False), [0.5, 0.125, 0.125, 0.25]
    )  # 2 cities, alike


def test_folds_deal_cities_in_turn_and_the_bootstrap_of_a_constant_gain_is_that_gain():
    assert folds_of(list("abcde"), 2) == [["a", "c", "e"], ["b", "d"]]
    with pytest.raises(ValueError):
        folds_of(list("ab"), 3)
    diff, low, high, wins = paired_bootstrap([0.1, 0.5, 0.3], [0.2, 0.6, 0.4], samples=200)
    assert diff == pytest.approx(0.1) and low == pytest.approx(0.1) and high == pytest.approx(0.1) and wins == 1.0
    diff, low, high, _ = paired_bootstrap([0.0, 0.0, 0.0, 0.0], [0.4, -0.4, 0.2, -0.2], samples=2000)
    assert diff == pytest.approx(0.0) and low < 0 < high


def test_a_tiny_finetune_writes_a_bundle_with_provenance_and_resumes_without_training_again(city, tmp_path, capfd):
    from csboundary.models.checkpoint import file_sha256, load_checkpoint, shipped_weights
    from csboundary.pipeline.prediction.patch import load_predictor
    from csboundary.pipeline.training.finetune import FinetuneBudget, finetune

    budget = FinetuneBudget(fpn_steps=2, afanet_steps=2, synthetic_cities=1, crop=128, batch=2)
    kwargs = dict(
        weights=None, work=tmp_path / "work", budget=budget, cache=tmp_path / "synthetic", device="cpu", progress=False
    )
    capfd.readouterr()
    done = finetune([city], tmp_path / "tuned.pt", **kwargs)
    assert (
        "render tiles" not in capfd.readouterr().err
    )  # progress=False (--quiet): the synthetic cities render without a bar
    bundle = load_checkpoint(tmp_path / "tuned.pt", ("bundle",))
    record = bundle["provenance"]["finetune"]
    assert record["base_sha256"] == file_sha256(shipped_weights())
    assert record["labelled"][0]["ground_truth_sha256"] == file_sha256(city / "ground_truth.gpkg")
    assert (
        record["budget"]["fpn_steps"] == 2
        and bundle["provenance"]["fpn"]["step"] == 2
        and bundle["provenance"]["afanet"]["step"] == 2
    )
    shipped = load_checkpoint(shipped_weights(), ("bundle",))
    assert bundle["inference"] == shipped["inference"] and bundle["confidence"] == shipped["confidence"]
    # one 600 px city gives too few edges to refit the confidence on: kept, and said why
    assert (
        record["edge_confidence"]["refitted"] is False
        and "a refit needs at least 100" in record["edge_confidence"]["reason"]
    )
    assert done["confidence"] == record["edge_confidence"]
    assert not all(torch.equal(bundle["fpn"][k], shipped["fpn"][k]) for k in shipped["fpn"])  # the FPN did learn
    assert load_predictor(tmp_path / "tuned.pt", "cpu", engine="torch") is not None
    stamps = {p: p.stat().st_mtime_ns for p in (done["work"] / "fpn" / "fpn.pt", done["work"] / "afanet" / "afanet.pt")}
    finetune([city], tmp_path / "again.pt", **kwargs)  # the same work folder: both runs are done already
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    with pytest.raises(InputError, match="other inputs or settings"):
        finetune(
            [city],
            tmp_path / "other.pt",
            **{**kwargs, "budget": FinetuneBudget(fpn_steps=3, afanet_steps=2, synthetic_cities=1)},
        )


def test_the_confidence_is_refitted_with_the_tuned_networks_only_on_enough_edges(city, tmp_path, monkeypatch):
    """With enough labelled edges the bundle's confidence is refitted on the labelled and the
    synthetic cities (its provenance names both); with too few it stays, byte for byte."""
    import shutil

    import csboundary.pipeline.training.confidence_fit as fit
    from csboundary.models.checkpoint import load_checkpoint, shipped_weights

    other = tmp_path / "synthetic"
    synthesize_city(other, seed=4, split="valid", config=style_config("classic", tile_size=SIZE), progress=False)
    bundle = tmp_path / "tuned.pt"
    shutil.copy(shipped_weights(), bundle)
    before = load_checkpoint(bundle, ("bundle",))["confidence"]
    monkeypatch.setattr(fit, "MIN_REFIT_EDGES", 10**6)
    kept = fit.refit_for_tuned(bundle, [city], [other], torch.device("cpu"), progress=False)
    assert (
        not kept["refitted"]
        and kept["labelled_edges"] > 0
        and load_checkpoint(bundle, ("bundle",))["confidence"] == before
    )
    monkeypatch.setattr(fit, "MIN_REFIT_EDGES", 1)
    monkeypatch.setattr(fit, "MIN_REFIT_CLASS", 0)
    done = fit.refit_for_tuned(bundle, [city], [other], torch.device("cpu"), progress=False)
    assert done["refitted"] and done["labelled_edges"] == kept["labelled_edges"]
    after = load_checkpoint(bundle, ("bundle",))["confidence"]
    assert after != before and [c["dir"] for c in after["provenance"]["cities"]] == [str(city), str(other)]


def test_cross_validation_scores_every_city_once_by_a_bundle_that_never_trained_on_it(tmp_path, monkeypatch):
    """The folds' bookkeeping, with fine-tuning and scoring stood in for: each held-out city is
    scored by its own fold's bundle, the means and gains are over all cities, and a finished fold
    is read back instead of being run again."""
    import csboundary.pipeline.evaluation.finetune_cv as cv
    from csboundary.data.synth.city import synthesize_city as synth

    for name in "abcd":
        synth(
            tmp_path / "set" / name,
            seed=1,
            split="valid",
            config=style_config("classic", tile_size=300),
            progress=False,
        )
    trained_on = {}

    def fake_finetune(train, out, **kwargs):
        trained_on[out.parent.name] = sorted(c.name for c in train)
        return {"seconds": {"fpn": 60.0, "afanet": 30.0}}

    def fake_scores(cities, weights, *args):
        tuned = "fold-" in str(weights)
        return {
            c.name: {
                "f1@5": 0.5 + (0.1 if tuned else 0.0) + 0.01 * "abcd".index(c.name),
                "apls": None if c.name == "d" else 0.4,
                "review": {
                    "corrected_minutes": (6.0 if tuned else 10.0) + "abcd".index(c.name),
                    "scratch_minutes": 8.0,
                    "km": 0.5,
                },
            }
            for c in cities
        }

    def fake_confidence(cities, tuned, base, *args):  # per held-out city: one true edge and one false
        return {
            "true": [True, False] * len(cities),
            "base": [0.4, 0.6] * len(cities),
            "tuned": [0.9, 0.2] * len(cities),
        }

    monkeypatch.setattr(cv, "finetune", fake_finetune)
    monkeypatch.setattr(cv, "_scores", fake_scores)
    monkeypatch.setattr(cv, "_held_out_confidence", fake_confidence)
    result = cv.evaluate_finetune(tmp_path / "set", tmp_path / "cv", folds=2, progress=False)
    assert trained_on == {"fold-0": ["b", "d"], "fold-1": ["a", "c"]}
    assert {n: r["fold"] for n, r in result["per_city"].items()} == {"a": 0, "c": 0, "b": 1, "d": 1}
    f1 = result["summary"]["f1@5"]
    assert (
        f1["base"] == pytest.approx(0.515)
        and f1["finetuned"] == pytest.approx(0.615)
        and f1["difference"] == pytest.approx(0.1)
    )
    assert result["summary"]["apls"]["base"] == pytest.approx(0.3)  # undefined counts 0, as in evaluate-set
    assert "1.5 min" in cv.format_finetune(result)
    # the mapping loop of fold 0: the base reviews b and d (11 + 13 min), the tuned re-drafts of a and c take 6 + 8
    loop = result["mapping_loop"][0]
    assert loop["train_review_minutes"] == 24.0 and loop["train_scratch_minutes"] == 16.0 and loop["train_km"] == 1.0
    assert (
        loop["held_out_tuned_minutes"] == 14.0
        and loop["held_out_base_minutes"] == 22.0
        and loop["held_out_scratch_minutes"] == 16.0
    )
    assert "review the training cities' drafts 24.0 min (24.0 min/km; from scratch 16.0)" in cv.format_finetune(result)
    confidence = result["confidence"]  # pooled over both folds' held-out edges
    assert confidence["edges"] == 8 and confidence["base"]["auc"] == 0.0 and confidence["tuned"]["auc"] == 1.0
    assert confidence["tuned"]["ece"] == pytest.approx(
        (0.1 * 4 + 0.2 * 4) / 8
    )  # bins 0.9 (all true) and 0.2 (all false)
    monkeypatch.setattr(cv, "finetune", lambda *a, **k: pytest.fail("a finished fold ran again"))
    assert (
        cv.evaluate_finetune(tmp_path / "set", tmp_path / "cv", folds=2, progress=False)["summary"] == result["summary"]
    )
