"""Enhanced-iCurb baseline: the expert, the history channel, start vertices, tracing, and a smoke
training whose checkpoint runs through the city pipeline."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig
from csboundary.labels.boundaries import Boundary
from csboundary.models.baselines import icurb
from csboundary.models.baselines.icurb import (
    Expert,
    ICurbConfig,
    Model,
    border_starts,
    history_channel,
    rollout,
    tracing,
)
from csboundary.models.checkpoint import load_checkpoint
from csboundary.models.training.config import TrainConfig
from csboundary.models.training.data import CitySpec, TrainingCity
from csboundary.pipeline.prediction.city import predict_city
from csboundary.pipeline.prediction.options import PredictionOptions


def line(*points, closed=False) -> Boundary:
    return Boundary(np.array(points, float), closed)


def test_expert_goes_step_px_ahead_in_the_travel_direction():
    expert = Expert([line((10, 50), (190, 50))], (200, 100), 20)
    target, stop = expert.act(np.array([50.0, 50.0]), np.array([1.0, 0.0]))
    assert np.allclose(target, (70, 50)) and not stop
    target, stop = expert.act(np.array([50.0, 53.0]), np.array([-1.0, 0.3]))  # off the line, heading back
    assert np.allclose(target, (30, 50)) and not stop


def test_expert_stops_at_the_end_and_at_the_window_border():
    expert = Expert([line((10, 50), (190, 50)), line((100, 70), (100, 300))], (200, 100), 20)
    target, stop = expert.act(np.array([180.0, 50.0]), np.array([1.0, 0.0]))
    assert np.allclose(target, (190, 50)) and stop
    target, stop = expert.act(np.array([100.0, 85.0]), np.array([0.0, 1.0]))
    assert np.allclose(target, (100, 100), atol=1e-6) and stop
    target, stop = expert.act(np.array([100.0, 85.0]), np.array([0.0, -1.0]))  # the other way: its end inside
    assert np.allclose(target, (100, 70)) and stop


def test_expert_closes_a_ring_at_its_start():
    ring = line((50, 50), (150, 50), (150, 150), (50, 150), (50, 50), closed=True)
    expert = Expert([ring], (200, 200), 20)
    target, stop = expert.act(np.array([50.0, 50.0]), np.array([1.0, 0.0]), start=(0, 0.0))
    assert np.allclose(target, (70, 50)) and not stop  # leaving the start does not stop
    target, stop = expert.act(np.array([50.0, 60.0]), np.array([0.0, -1.0]), start=(0, 0.0))
    assert np.allclose(target, (50, 50)) and stop
    target, stop = expert.act(np.array([60.0, 50.0]), np.array([-1.0, 0.0]), start=(0, 0.0))  # counter-clockwise
    assert np.allclose(target, (50, 50)) and stop


def test_starts_are_border_crossings_heading_inwards():
    starts = Expert([line((-30, 50), (230, 50))], (200, 100), 20).starts()
    got = sorted((tuple(np.round(p, 6)), tuple(np.round(d, 6))) for p, d, _ in starts)
    assert got == [((0.0, 50.0), (1.0, 0.0)), ((200.0, 50.0), (-1.0, 0.0))]


def test_history_channel_draws_the_recent_path():
    history = torch.tensor([[[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]]])  # heading right, the ROI centred on (20, 0)
    image = history_channel(history, 32)[0, 0]
    assert image.shape == (32, 32)
    assert image[15:17, :15].min() == 1  # behind the current vertex, on the path
    assert image[15:17, 18:].max() == 0 and image[:12].max() == 0 and image[20:].max() == 0
    dot = history_channel(torch.tensor([[[5.0, 5.0], [5.0, 5.0]]]), 32)[0, 0]  # no path yet: a dot
    assert dot[15:17, 15:17].min() == 1 and dot.sum() < 20


def drawn_line(a, b, size: int, width: float = 1.6) -> np.ndarray:
    """A segmentation map with the segment a -> b drawn ``2 * width`` px wide."""
    rows, cols = np.mgrid[0:size, 0:size] + 0.5
    a, b = np.asarray(a, float), np.asarray(b, float)
    t = np.clip(((cols - a[0]) * (b - a)[0] + (rows - a[1]) * (b - a)[1]) / ((b - a) ** 2).sum(), 0, 1)
    return (np.hypot(cols - a[0] - t * (b - a)[0], rows - a[1] - t * (b - a)[1]) < width).astype(np.float32)


def test_start_vertices_where_the_segmentation_meets_the_border():
    a, b = np.array([0.0, 40.0]), np.array([200.0, 160.0])
    seg = drawn_line(a, b, 200)
    seg[100:110, 20:30] = 1  # a blob away from the border gives no start
    starts = border_starts(seg, 0.5, 4)
    assert len(starts) == 2
    for truth in (a, b):
        assert np.min(np.linalg.norm(starts - truth, axis=1)) < 3


def wave() -> Boundary:
    x = np.arange(-20.0, 321.0, 5.0)
    return Boundary(np.stack([x, 150 + 60 * np.sin(x / 100)], 1), False)


class ExpertAgent:
    """A stand-in agent returning the expert's action for the states ``rollout`` asks about
    (it reads the histories from ``agent_input``, which it wraps). It starts heading for the
    window centre."""

    def __init__(self, expert: Expert, centre, monkeypatch):
        self.expert, self.centre, self.histories = expert, np.asarray(centre, float), None
        original = tracing.agent_input

        def spy(tensor, history, roi):
            self.histories = history.cpu().numpy()
            return original(tensor, history, roi)

        monkeypatch.setattr(tracing, "agent_input", spy)  # where rollout looks it up

    def __call__(self, x):
        offsets, logits = [], []
        for h in self.histories:
            d = h[-1] - h[-2]
            if np.linalg.norm(d) < 1e-6:
                d = self.centre - h[-1]
            target, stop = self.expert.act(h[-1], d)
            offsets.append(target - h[-1])
            logits.append(10.0 if stop else -10.0)
        return torch.tensor(np.array(offsets), dtype=torch.float32), torch.tensor(logits)

    def eval(self):
        return self


def test_tracing_with_the_expert_as_agent_reproduces_the_boundary(monkeypatch):
    config = ICurbConfig(roi=32)
    expert = Expert([wave()], (300, 300), config.step_px)
    starts = expert.starts()
    assert len(starts) == 2
    agent = ExpertAgent(expert, (150, 150), monkeypatch)
    traces, records = rollout(agent, torch.zeros(5, 300, 300), np.array([s[0] for s in starts]), config)
    graph = traces.graph()
    assert records == [] and graph.n_edges >= 300 / 20
    assert max(expert.nearest(v)[2] for v in graph.vertices) < 2  # every vertex on the boundary
    samples = expert.at(0, np.arange(0, expert.cums[0][-1], 2.0))
    samples = samples[(samples >= 0).all(1) & (samples <= 300).all(1)]
    traced = Expert([Boundary(graph.edge_polyline(k), False) for k in range(graph.n_edges)], (300, 300), 20)
    assert max(traced.nearest(p)[2] for p in samples) < 2  # and the boundary all traced
    n, _ = connected_components(coo_matrix((np.ones(graph.n_edges), graph.edges.T), shape=(graph.n_vertices,) * 2))
    assert n == 1  # the two traces met and joined
    assert graph.edge_scores.min() > 0.99


def test_at_a_mosaic_edge_the_imagery_edge_is_the_border(monkeypatch):
    """Zero padding around the imagery (a mosaic edge): starts and stops are on the imagery's edge."""
    a, b = (50.0, 120.0), (250.0, 180.0)
    frame = np.zeros((300, 300), bool)
    frame[50:250, 50:250] = True
    maps = (drawn_line(a, b, 300) * frame)[None]
    image = np.where(frame, 90, 0).astype(np.uint8)[None].repeat(4, 0)
    expert = Expert([line(a, b)], (300, 300), 20)
    model = Model(ExpertAgent(expert, (150, 150), monkeypatch), ICurbConfig(roi=32), None, torch.device("cpu"))
    found = model.extract(maps)
    assert found.n_vertices == 0  # nothing reaches the window border
    graph = model.connect(None, image, maps, found)
    assert graph.n_edges >= 10 and max(expert.nearest(v)[2] for v in graph.vertices) < 2
    xs = graph.vertices[:, 0]
    assert xs.min() < 55 and xs.max() > 245 and xs.min() >= 50 and xs.max() <= 250


def test_rollout_with_beta_one_follows_the_teacher_and_labels_states():
    config = ICurbConfig(roi=16, widths=(4,), hidden=4, max_steps=5)
    expert = Expert([wave()], (300, 300), config.step_px)
    starts = expert.starts()
    agent = icurb.Agent(config).eval()
    traces, records = rollout(
        agent,
        torch.zeros(5, 300, 300),
        np.array([s[0] for s in starts]),
        config,
        expert.teacher(starts),
        beta=1.0,
        rng=np.random.default_rng(0),
    )
    x, offsets, stops = records[0]
    assert x.shape == (2, 6, 16, 16) and np.allclose(np.linalg.norm(offsets, axis=1), 20, atol=1e-3) and not stops.any()
    assert max(expert.nearest(v)[2] for v in traces.graph().vertices) < 1e-6


def test_unknown_option_is_an_error():
    with pytest.raises(ValueError, match="unknown icurb option"):
        icurb.split_options({"rio": 32})


def test_smoke_training_gives_a_model_the_city_pipeline_runs(tmp_path):
    cache = tmp_path / "cities"
    specs = {split: {"split": split, "seed": 1, "tiles": [1, 1], "tile_size": 600} for split in ("train", "valid")}
    for spec in specs.values():
        path = CitySpec(spec["split"], 1, (1, 1), 600).path(cache)
        synthesize_city(path, 1, spec["split"], (1, 1), SynthConfig(tile_size=600, gsd=0.3), progress=False)
    options = {"roi": 32, "widths": [8, 8], "hidden": 16, "window": 256, "batch": 8, "buffer": 512, "max_steps": 15}
    config = TrainConfig.from_dict(
        {
            "model": "icurb",
            "cache": str(cache),
            "train_city": specs["train"],
            "valid_city": specs["valid"],
            "steps": 5,
            "validate_every": 5,
            "validation_samples": 1,
            "options": options,
        }
    )
    weights = icurb.train(config, tmp_path / "run", torch.device("cpu"), progress=False)
    payload = load_checkpoint(weights, ("icurb",))
    assert payload["step"] == 5 and payload["validation"][0]["step"] == 5 and "optimizer" not in payload
    assert (tmp_path / "run" / "icurb-last.pt").exists()
    events = [json.loads(line)["event"] for line in (tmp_path / "run" / "train.log").read_text().splitlines()]
    assert events == ["start", "validate", "done"]

    model = Model.load(weights, torch.device("cpu"))
    city = TrainingCity(CitySpec("valid", 1, (1, 1), 600).path(cache))
    windows = []
    result = predict_city(
        city.mosaic, model, PredictionOptions(progress=False), on_window=lambda patch, maps: windows.append(maps.shape)
    )
    assert windows == [(1, 1100, 1100)]
    graph = result.patch_graphs[(0, 0)]
    assert len(graph.edge_scores) == graph.n_edges


def test_a_step_leaving_the_window_ends_on_its_border():
    point, left = icurb.clip_step(np.array([10.0, 10.0]), np.array([-10.0, 30.0]), (0, 0, 100, 100))
    assert left and np.allclose(point, (0, 20))
    point, left = icurb.clip_step(np.array([60.0, 90.0]), np.array([70.0, 95.0]), (50, 50, 250, 250))
    assert not left and np.allclose(point, (70, 95))
