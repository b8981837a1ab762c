"""Sat2Graph baseline: graph tensor round trips, augmentation consistency, training and inference."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig
from csboundary.data.windows import PixelWindow
from csboundary.graph import BoundaryGraph
from csboundary.models.baselines import baseline_module
from csboundary.models.baselines.sat2graph import (
    CHANNELS,
    Model,
    Sat2GraphOptions,
    augment_with_graph,
    decode_adjacency,
    decode_edges,
    edge_slots,
    encode_graph,
    owner_map,
    sat2graph_loss,
    train,
    training_sample,
)
from csboundary.models.checkpoint import load_checkpoint
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.data import CitySpec, TrainingCity

TINY_FPN = {"widths": [8, 8, 8, 8], "blocks": [1, 1, 1, 1], "pyramid": 8, "stem": 8}
NO_CAP = Sat2GraphOptions(max_degree=None)


def round_trip(vertices, edges, options=NO_CAP, shape=(400, 400)):
    target, mask = encode_graph(np.asarray(vertices, float), np.asarray(edges), shape, options)
    return decode_edges(vertices, target, options), target, mask


def star(n_angles=6, length=100.0, centre=(200.3, 199.6)):
    angles = np.radians(60.0 * np.arange(n_angles))
    return np.vstack([centre, np.array(centre) + length * np.stack([np.cos(angles), np.sin(angles)], 1)])


def test_square_round_trip_recovers_exact_edges():
    vertices = [(100.5, 100.5), (200.5, 100.5), (200.5, 200.5), (100.5, 200.5)]
    edges = [(0, 1), (1, 2), (2, 3), (0, 3)]
    for options in (NO_CAP, Sat2GraphOptions()):
        decoded, target, mask = round_trip(vertices, edges, options)
        assert decoded == sorted(edges)
    assert target.shape == (CHANNELS, 400, 400) and target.dtype == np.float32
    owner = owner_map(np.array(vertices), (400, 400), 3.0)
    assert (target[0] == (owner >= 0)).all() and (owner >= 0).sum() == 4 * 29  # 29 pixel centres within 3 px of one
    assert (mask[0] == 1).all() and (mask[1] == target[0]).all()  # existence supervised on discs only
    assert (mask[2:4] == target[1]).all()  # vectors only where the slot exists
    probs = decode_adjacency(vertices, target, NO_CAP)
    assert np.allclose(probs, probs.T) and probs[0, 2] == 0 and probs[0, 1] == 1


def test_t_junction_needs_degree_three():
    vertices = [(150.5, 150.5), (50.5, 150.5), (250.5, 150.5), (150.5, 250.5)]
    edges = [(0, 1), (0, 2), (0, 3)]
    assert round_trip(vertices, edges)[0] == sorted(edges)
    assert len(round_trip(vertices, edges, Sat2GraphOptions(max_degree=2))[0]) == 2  # csBoundary's cap


def test_neighbours_on_sector_boundaries_get_one_sector_each():
    vertices = star()
    edges = [(0, i) for i in range(1, 7)]
    assert edge_slots(vertices, edges)[0].tolist() == [1, 2, 3, 4, 5, 6]  # angle 60k -> sector k
    assert round_trip(vertices, edges)[0] == edges


def test_two_neighbours_in_one_sector_nearer_wins_farther_recovered_from_its_side():
    vertices = np.array([(200.5, 200.5), (250.5, 210.5), (270.5, 260.5)])  # both at 11 and 40 degrees
    edges = [(0, 1), (0, 2)]
    slots = edge_slots(vertices, edges)
    assert slots[0, 0] == 1 and (slots[0, 1:] == -1).all()
    assert round_trip(vertices, edges)[0] == edges  # vertex 2's own slot points back to 0


def test_edge_longer_than_max_edge_is_clipped_then_lost_or_snapped():
    options = Sat2GraphOptions(max_edge_px=250, snap_px=15)
    far = [(50.5, 150.5), (350.5, 150.5)]  # 300 px: clipped tip at 250 px, 50 px short of the neighbour
    decoded, target, _ = round_trip(far, [(0, 1)], options)
    assert decoded == [] and target[2, 150, 50] == 1.0  # sector 0 of vertex 0, dx clipped to 1
    near = [(50.5, 150.5), (310.5, 150.5)]  # 260 px: the clipped tip is 10 px off, within snap_px
    assert round_trip(near, [(0, 1)], options)[0] == [(0, 1)]
    decoy = [(50.5, 150.5), (350.5, 150.5), (303.5, 155.5)]  # a vertex near the clipped tip takes it
    assert round_trip(decoy, [(0, 1)], options)[0] == [(0, 2)]


def test_close_vertices_split_their_discs_and_keep_their_edges():
    vertices = [(100.5, 100.5), (104.5, 100.5), (100.5, 160.5), (104.5, 40.5)]
    edges = [(0, 1), (0, 2), (1, 3)]
    decoded, target, _ = round_trip(vertices, edges)
    assert decoded == sorted(edges)


def test_augmented_graph_encodes_like_the_augmented_image():
    size = 64
    vertices = np.array([(10.5, 12.5), (40.5, 20.5), (30.5, 50.5), (55.5, 45.5)])
    edges = np.array([(0, 1), (1, 2), (2, 3)])
    target, _ = encode_graph(vertices, edges, (size, size), NO_CAP)
    seen = set()
    for seed in range(32):
        image = np.zeros((len(vertices), size, size), np.float32)  # one marker band per vertex
        for i, (x, y) in enumerate(vertices):
            image[i, int(y), int(x)] = 1
        rng = np.random.default_rng(seed)
        moved, image_aug, vertexness_aug = augment_with_graph(rng, vertices, image, target[0])
        markers = np.array([np.argwhere(band)[0][::-1] + 0.5 for band in image_aug])
        assert np.allclose(moved, markers)  # the graph follows the image
        new, _ = encode_graph(moved, edges, (size, size), NO_CAP)
        assert np.array_equal(new[0], vertexness_aug)
        owner = owner_map(moved, (size, size), NO_CAP.radius_px)
        for u, v in [(a, b) for a, b in edges] + [(b, a) for a, b in edges]:  # u's disc holds (v - u) in some slot
            r, c = np.argwhere(owner == u)[0]
            slots = new[1:, r, c].reshape(6, 3)  # (existence, dx, dy) per slot
            vectors = slots[slots[:, 0] == 1, 1:]
            assert np.isclose(vectors, (markers[v] - markers[u]) / NO_CAP.max_edge_px).all(1).any()
        assert decode_edges(moved, new, NO_CAP) == sorted(map(tuple, edges.tolist()))
        seen.add(tuple(np.round(moved[0], 1)))
    assert len(seen) == 8  # all flips and rotations were exercised


def test_unknown_option_is_an_error():
    with pytest.raises(ValueError, match="unknown sat2graph option"):
        Sat2GraphOptions.from_dict({"snap": 3})


# -- training and inference on a tiny synthetic city ----------------------------------------------


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """A 600 px train city (coarse 0.3 m pixels: more streets per pixel), reused as the valid city."""
    cache = tmp_path_factory.mktemp("cities")
    spec = CitySpec("train", 3, (1, 1), 600)
    synthesize_city(spec.path(cache), 3, "train", (1, 1), SynthConfig(tile_size=600, gsd=0.3), progress=False)
    return cache


def tiny_config(cache, **overrides) -> TrainConfig:
    city = {"split": "train", "seed": 3, "tiles": [1, 1], "tile_size": 600}
    base = {
        "model": "sat2graph",
        "cache": str(cache),
        "train_city": city,
        "valid_city": city,
        "steps": 3,
        "validate_every": 2,
        "validation_samples": 1,
        "crop": 96,
        "batch": 2,
        "fpn": TINY_FPN,
        "options": {"snap_px": 12.0},
    }
    return TrainConfig.from_dict({**base, **overrides})


@pytest.fixture(scope="module")
def run(cache, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    return out, train(tiny_config(cache), out, torch.device("cpu"), progress=False)


def test_training_writes_checkpoint_log_and_validation(run):
    out, weights = run
    payload = load_checkpoint(weights, ("sat2graph",))
    assert payload["step"] == 3 and [v["step"] for v in payload["validation"]] == [2, 3]
    assert payload["sat2graph_config"]["out_channels"] == CHANNELS and payload["train_config"]["options"] == {
        "snap_px": 12.0
    }
    assert {"val_vertex_f1", "val_slot_f1", "val_edge_f1"} <= set(payload["validation"][-1])
    events = [json.loads(line)["event"] for line in (out / "train.log").read_text().splitlines()]
    assert events == ["start", "validate", "validate", "done"]
    assert baseline_module("sat2graph").train is train


def test_resumed_run_equals_uninterrupted_run(run, cache, tmp_path):
    _, weights = run
    train(tiny_config(cache, steps=2), tmp_path, torch.device("cpu"), progress=False)
    resumed = train(
        tiny_config(cache), tmp_path, torch.device("cpu"), resume=str(tmp_path / "sat2graph-last.pt"), progress=False
    )
    a, b = load_checkpoint(weights, ("sat2graph",))["sat2graph"], load_checkpoint(resumed, ("sat2graph",))["sat2graph"]
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_model_predicts_a_1100_px_window(run, cache):
    _, weights = run
    model = Model.load(weights, torch.device("cpu"))  # keypoints: csBoundary's shipped FPN
    assert model.options.snap_px == 12.0
    city = TrainingCity(CitySpec("train", 3, (1, 1), 600).path(cache))
    image = city.mosaic.read(PixelWindow(-250, -250, 1100, 1100)).data
    (maps,) = model.patch_maps([None], [image])
    assert maps.shape == (1 + CHANNELS, 1100, 1100) and maps.dtype == np.float32
    assert maps[[0, 1, 2]].min() >= 0 and maps[[0, 1, 2]].max() <= 1 and np.abs(maps[3:5]).max() <= 1
    found = model.extract(maps)
    assert found.n_vertices > 0  # the shipped FPN finds the synthetic city's keypoints
    graph = model.connect(None, image, maps, found)
    assert isinstance(graph, BoundaryGraph) and np.array_equal(graph.vertices, found.vertices)
    corner = {tuple(sorted(e)) for e in found.edges.tolist()}
    assert corner <= {tuple(sorted(e)) for e in graph.edges.tolist()}  # csBoundary's corner edges kept
    assert np.bincount(graph.edges.ravel(), minlength=graph.n_vertices).max() <= 2


def test_loss_falls_when_overfitting_one_crop(cache):
    torch.manual_seed(0)
    options = Sat2GraphOptions()
    city = TrainingCity(CitySpec("train", 3, (1, 1), 600).path(cache))
    window = max(
        (PixelWindow(c, r, 64, 64) for r in range(0, 537, 67) for c in range(0, 537, 67)),
        key=lambda w: training_sample(city, w, options)[1][1::3].sum(),
    )  # the crop with the most slot pixels
    image, target, mask, _, _ = (
        torch.from_numpy(np.ascontiguousarray(a))[None] for a in training_sample(city, window, options)
    )
    assert target[0, 1::3].sum() > 0
    net = FPN(FPNConfig.from_dict({**TINY_FPN, "out_channels": CHANNELS}))
    optimizer = torch.optim.Adam(net.parameters(), lr=3e-3)
    losses = []
    for _ in range(60):
        loss = sat2graph_loss(net(image.float()), target, mask, options)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert math.isfinite(losses[-1]) and np.mean(losses[-5:]) < 0.6 * np.mean(losses[:5])
