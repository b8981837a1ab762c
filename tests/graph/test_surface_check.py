"""The road-surface check: an edge's roadway-beside-it score, and the hysteresis that keeps a
curb's weak stretches with its sure ones."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph import BoundaryGraph
from csboundary.graph.end_joining import EndJoinConfig
from csboundary.graph.settings import GraphOverrides, GraphSettings
from csboundary.graph.surface_check import SurfaceCheckConfig, kept_by_hysteresis, side_surface, surface_checked


def graph(vertices, edges) -> BoundaryGraph:
    return BoundaryGraph(np.asarray(vertices, float).reshape(-1, 2), np.asarray(edges, np.int64).reshape(-1, 2))


def test_an_edge_along_the_roadway_scores_one_and_an_edge_in_a_lawn_scores_zero():
    surface = np.zeros((100, 100), np.float32)
    surface[:15] = 1.0  # roadway above row 15
    g = graph([[10, 20], [50, 20], [10, 80], [50, 80]], [[0, 1], [2, 3]])
    # the first edge's points at y = 20: 8 px above (row 12) is roadway, below (row 28) is not
    assert side_surface(g, surface, 8.0).tolist() == [1.0, 0.0]
    # read 4 px away instead, neither side of the first edge reaches the roadway
    assert side_surface(g, surface, 4.0).tolist() == [0.0, 0.0]


def test_the_score_is_the_mean_over_the_points_of_the_edge():
    surface = np.zeros((100, 100), np.float32)
    surface[:15, :30] = 1.0  # roadway beside the first 20 of the edge's 41 points (x = 10 .. 29.x)
    g = graph([[10, 20], [50, 20]], [[0, 1]])
    assert side_surface(g, surface, 8.0)[0] == pytest.approx(20 / 41)


def test_hysteresis_keeps_weak_edges_connected_to_a_sure_one_and_drops_the_rest():
    # a chain 0-1-2-3 (scores 0.9, 0.3, 0.1) and a separate pair 4-5-6 (0.3, 0.3)
    edges = np.array([[0, 1], [1, 2], [2, 3], [4, 5], [5, 6]])
    scores = np.array([0.9, 0.3, 0.1, 0.3, 0.3])
    kept = kept_by_hysteresis(edges, 7, scores, strong=0.5, weak=0.2)
    assert kept.tolist() == [True, True, False, False, False]
    # the weak edge below the floor does not carry the connection on: 3-7 hangs off it
    edges2 = np.vstack([edges, [[3, 7]]])
    kept2 = kept_by_hysteresis(edges2, 8, np.append(scores, 0.4), strong=0.5, weak=0.2)
    assert kept2.tolist() == [True, True, False, False, False, False]


def test_the_check_is_off_by_default_and_drops_unbordered_edges_when_on():
    surface = np.zeros((100, 100), np.float32)
    surface[:15] = 1.0
    g = graph([[10, 20], [50, 20], [10, 80], [50, 80]], [[0, 1], [2, 3]])
    assert surface_checked(g, surface, SurfaceCheckConfig()) is g
    out = surface_checked(g, surface, SurfaceCheckConfig(strong=0.5))
    assert out.n_edges == 1 and np.allclose(out.vertices[out.edges[0]], [[10, 20], [50, 20]])


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(0, 2 * math.pi), length=st.floats(20, 80), side=st.sampled_from([1.0, -1.0]))
def test_a_straight_edge_beside_a_half_plane_of_roadway_scores_one_either_way_round(angle, length, side):
    centre = np.array([100.0, 100.0])
    d = np.array([math.cos(angle), math.sin(angle)])
    normal = np.array([-d[1], d[0]])
    rows, cols = np.mgrid[0:200, 0:200]
    signed = (cols + 0.5 - centre[0]) * normal[0] + (rows + 0.5 - centre[1]) * normal[1]
    surface = (side * signed > 2).astype(np.float32)  # roadway on one side, from 2 px beyond the line
    a, b = centre - d * length / 2, centre + d * length / 2
    forward, backward = graph([a, b], [[0, 1]]), graph([b, a], [[0, 1]])
    assert side_surface(forward, surface, 8.0)[0] == pytest.approx(1.0)
    assert side_surface(backward, surface, 8.0)[0] == pytest.approx(1.0)
    assert side_surface(forward, np.zeros_like(surface), 8.0)[0] == 0.0


def test_the_predictor_checks_only_maps_that_carry_a_surface_channel():
    from csboundary.pipeline.prediction.patch import PatchPredictor

    g = graph([[10, 20], [50, 20], [10, 80], [50, 80]], [[0, 1], [2, 3]])
    host = SimpleNamespace(settings=GraphSettings(join=EndJoinConfig(), surface=SurfaceCheckConfig(strong=0.5)))
    host.filled = lambda patch, maps, graph: graph
    two = np.zeros((2, 100, 100), np.float32)
    assert PatchPredictor.finished(host, None, two, g).n_edges == 2  # an FPN without the surface head
    three = np.zeros((3, 100, 100), np.float32)
    three[2, :15] = 1.0
    assert PatchPredictor.finished(host, None, three, g).n_edges == 1


def test_bundle_carries_the_surface_check_only_with_an_fpn_that_has_the_head(tmp_path):
    import torch

    from csboundary.errors import InputError
    from csboundary.graph.settings import GraphSettings
    from csboundary.models.checkpoint import load_checkpoint, save_checkpoint
    from csboundary.models.fpn import FPNConfig, fpn_for_weights
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor
    from helpers import bundle_without, shipped_parts

    fpn_path, afanet_path = shipped_parts(tmp_path)  # the shipped FPN has the head
    shipped = load_checkpoint(fpn_path, ("fpn",))
    assert shipped["fpn_config"]["surface"]
    # the option works on the shipped weights
    assert load_predictor(None, "cpu", GraphOverrides(surface_check=0.5), engine="torch").settings.surface.strong == 0.5
    assert (
        load_predictor(None, "cpu", engine="torch").settings.surface.strong == 0.5
    )  # on by default since the model card's choice
    assert not load_predictor(
        None, "cpu", GraphOverrides(surface_check=0.0), engine="torch"
    ).settings.surface.active  # and 0 turns it off
    plain = {
        k: v for k, v in shipped["fpn"].items() if not k.startswith("surface_head.")
    }  # an FPN from before the head
    save_checkpoint(tmp_path / "plain.pt", "fpn", fpn=plain, fpn_config={**shipped["fpn_config"], "surface": False})
    with pytest.raises(InputError, match="surface head"):
        make_bundle(tmp_path / "plain.pt", afanet_path, tmp_path / "no.pt", GraphSettings().replaced(surface_check=0.5))
    make_bundle(tmp_path / "plain.pt", afanet_path, tmp_path / "plain-bundle.pt")
    with pytest.raises(InputError, match="surface head"):
        load_predictor(tmp_path / "plain-bundle.pt", "cpu", GraphOverrides(surface_check=0.5), engine="torch")
    config = {**shipped["fpn_config"], "surface": True}
    model = fpn_for_weights(config)
    missing, _ = model.load_state_dict(plain, strict=False)
    assert missing and all(k.startswith("surface_head.") for k in missing)
    save_checkpoint(
        tmp_path / "fpn-surface.pt", "fpn", fpn=model.state_dict(), fpn_config=FPNConfig.from_dict(config).to_dict()
    )
    make_bundle(
        tmp_path / "fpn-surface.pt",
        afanet_path,
        tmp_path / "b.pt",
        GraphSettings().replaced(surface_check=0.6, surface_weak=0.25),
    )
    predictor = PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu"))
    assert (
        predictor.settings.surface.strong,
        predictor.settings.surface.weak,
        predictor.settings.surface.offset_px,
    ) == (0.6, 0.25, 8.0)
    assert predictor.maps(np.zeros((4, 128, 128), np.uint8)).shape == (3, 128, 128)
    off = load_predictor(tmp_path / "b.pt", "cpu", GraphOverrides(surface_check=0), engine="torch")
    # nothing reads the surface
    assert not off.settings.surface.active and off.maps(np.zeros((4, 128, 128), np.uint8)).shape == (2, 128, 128)
    bundle_without(tmp_path / "b.pt", tmp_path / "older.pt", ("surface_check", "surface_weak", "surface_offset"))
    assert not PatchPredictor.load(tmp_path / "older.pt", torch.device("cpu")).settings.surface.active


def _side_surface_per_edge(g: BoundaryGraph, surface: np.ndarray, offset_px: float) -> np.ndarray:
    """The definition, one edge at a time (the loop side_surface replaced)."""
    from csboundary.graph.edge_support import points_along

    h, w = surface.shape
    scores = np.zeros(g.n_edges)
    for k in range(g.n_edges):
        line = np.asarray(g.edge_polyline(k), float)
        steps = np.diff(line, axis=0)
        lengths = np.linalg.norm(steps, axis=1)
        keep = lengths > 1e-9
        if not keep.any():
            continue
        starts, steps, lengths = line[:-1][keep], steps[keep], lengths[keep]
        points, segment, _, _ = points_along(starts, starts + steps)
        normals = np.stack([-steps[:, 1], steps[:, 0]], axis=1)[segment] / lengths[segment, None]
        sides = [
            surface[np.clip(np.floor(q[:, 1]).astype(int), 0, h - 1), np.clip(np.floor(q[:, 0]).astype(int), 0, w - 1)]
            for q in (points + offset_px * normals, points - offset_px * normals)
        ]
        scores[k] = float(np.maximum(*sides).mean())
    return scores


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 12), st.floats(0.0, 12.0))
def test_all_edges_at_once_score_as_one_edge_at_a_time(seed, n_edges, offset):
    rng = np.random.default_rng(seed)
    surface = rng.random((60, 80)).astype(np.float32)
    vertices = rng.uniform(-10, 90, (2 * n_edges, 2))
    vertices[1::4] = vertices[0::4][: len(vertices[1::4])]  # some zero-length edges
    polylines = [
        np.vstack([vertices[2 * k], rng.uniform(-10, 90, (int(rng.integers(0, 4)), 2)), vertices[2 * k + 1]])
        for k in range(n_edges)
    ]
    g = BoundaryGraph(vertices, np.arange(2 * n_edges).reshape(-1, 2), edge_polylines=polylines)
    assert np.allclose(side_surface(g, surface, offset), _side_surface_per_edge(g, surface, offset), atol=1e-6)
    assert side_surface(graph(np.zeros((0, 2)), np.zeros((0, 2))), surface, offset).shape == (0,)


def test_an_edge_across_the_roadway_has_roadway_on_both_sides_and_goes_with_both_sides_on():
    surface = np.zeros((100, 100), np.float32)
    surface[20:60] = 1.0  # a street from row 20 to row 60
    # a curb along row 20 (roadway below only) and a straight edge across the street at x = 50
    g = graph([[10, 20], [90, 20], [50, 22], [50, 58]], [[0, 1], [2, 3]])
    assert side_surface(g, surface, 8.0, poorer=True).tolist() == [0.0, 1.0]
    out = surface_checked(g, surface, SurfaceCheckConfig(strong=0.5, both_sides=0.5))
    assert out.n_edges == 1 and np.allclose(out.vertices[out.edges[0]], [[10, 20], [90, 20]])
    # off (the default), the edge across stays: it has roadway beside it
    assert surface_checked(g, surface, SurfaceCheckConfig(strong=0.5)).n_edges == 2
