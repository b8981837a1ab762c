"""OrientationRefine: orientation labels, augmentation of direction vectors, corruption, training, inference."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig
from csboundary.data.windows import PixelWindow
from csboundary.models.baselines import baseline_module
from csboundary.models.baselines.orientation_refine import (
    IGNORE,
    KIND,
    Model,
    augment_with_vectors,
    corrupt,
    orientation_classes,
    train,
)
from csboundary.models.checkpoint import load_checkpoint
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.data import CitySpec, TrainingCity

TINY_FPN = {"widths": [8, 8, 8, 8], "blocks": [1, 1, 1, 1], "pyramid": 8, "stem": 8}


def test_orientation_classes_are_undirected_bins():
    vectors = np.zeros((2, 1, 4))
    vectors[:, 0, 0] = [1, 0]  # along +col: 0 deg
    vectors[:, 0, 1] = [-1, 0]  # the same line walked the other way
    vectors[:, 0, 2] = [0, -1]  # up the image: 90 deg
    vectors[:, 0, 3] = [math.cos(math.radians(100)), -math.sin(math.radians(100))]
    classes = orientation_classes(vectors, np.array([[True, True, True, False]]), bins=4)
    assert classes.tolist() == [[0, 0, 2, IGNORE]]


@pytest.mark.parametrize("seed", range(8))
def test_augmented_vectors_point_along_the_augmented_line(seed):
    # A line from (col 2, row 3) to (col 12, row 5) drawn into an image, with its direction vector
    # on the line's pixels; after augmentation the vector must join the moved endpoints.
    image = np.zeros((1, 16, 20), np.float32)
    image[0, 3, 2], image[0, 5, 12] = 1.0, 2.0  # the two ends, told apart by value
    vectors = np.zeros((2, 16, 20), np.float32)
    vectors[:, 3, 2] = np.array([10, 2]) / math.hypot(10, 2)
    moved_vectors, moved = augment_with_vectors(np.random.default_rng(seed), vectors, image)
    (r0, c0), (r1, c1) = np.argwhere(moved[0] == 1.0)[0], np.argwhere(moved[0] == 2.0)[0]
    v = moved_vectors[:, r0, c0]
    expected = np.array([c1 - c0, r1 - r0]) / math.hypot(c1 - c0, r1 - r0)
    assert np.allclose(v, expected, atol=1e-6)


def test_corruption_cuts_gaps_and_keeps_values_in_range():
    seg = np.zeros((96, 96), np.float32)
    seg[47:50, :] = 1
    out = corrupt(seg, np.random.default_rng(0))
    assert out.min() >= 0 and out.max() <= 1
    assert (out[48] < 0.5).sum() >= 5  # at least one gap across the line


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cities")
    synthesize_city(
        CitySpec("train", 3, (1, 1), 600).path(cache),
        3,
        "train",
        (1, 1),
        SynthConfig(tile_size=600, gsd=0.3),
        progress=False,
    )
    return cache


@pytest.fixture(scope="module")
def run(cache, tmp_path_factory):
    city = {"split": "train", "seed": 3, "tiles": [1, 1], "tile_size": 600}
    config = TrainConfig.from_dict(
        {
            "model": KIND,
            "cache": str(cache),
            "train_city": city,
            "valid_city": city,
            "steps": 4,
            "validate_every": 2,
            "validation_samples": 1,
            "crop": 96,
            "batch": 2,
            "fpn": TINY_FPN,
            "options": {"refine_fraction": 0.5, "refiner": TINY_FPN},
        }
    )
    out = tmp_path_factory.mktemp("run")
    return out, train(config, out, torch.device("cpu"), progress=False)


def test_training_runs_both_stages_and_checkpoints(run):
    out, weights = run
    payload = load_checkpoint(weights, (KIND,))
    assert payload["step"] == 4 and [v["stage"] for v in payload["validation"]] == [1, 2]
    assert "val_refined_seg_f1" in payload["validation"][-1] and "val_refined_seg_f1" not in payload["validation"][0]
    assert [json.loads(line)["event"] for line in (out / "train.log").read_text().splitlines()] == [
        "start",
        "validate",
        "validate",
        "done",
    ]
    assert baseline_module(KIND).train is train


def test_model_maps_and_graph_of_a_window(run, cache):
    _, weights = run
    model = Model.load(weights, torch.device("cpu"))
    city = TrainingCity(CitySpec("train", 3, (1, 1), 600).path(cache))
    image = city.mosaic.read(PixelWindow(-250, -250, 1100, 1100)).data
    (maps,) = model.patch_maps([None], [image])
    assert maps.shape == (1, 1100, 1100) and 0 <= maps.min() and maps.max() <= 1
    maps = np.zeros_like(maps)
    maps[0, 500:503, 100:900] = 1.0  # a drawn boundary: one straight edge
    graph = model.connect(None, image, maps, model.extract(maps))
    assert graph.n_edges == 1 and abs(graph.edge_lengths()[0] - 799) <= 3
