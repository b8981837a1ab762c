"""The roadway's outline in place of the edges along it: a street of known width, edges cut where
the outline takes over, short unsure stretches bridged, points moved onto the boundary ridge."""

import numpy as np
import pytest

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.outline_fusion import (
    OUTLINE,
    OutlineConfig,
    bridged,
    cut_along,
    fused_with_outline,
    placed_on_ridge,
)

H, W = 120, 300
TOP, BOTTOM = 40, 80  # the roadway: rows 40..79


def street(surface_inside: float = 1.0, surface_outside: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A horizontal street across the window: surface map and a boundary map with one-pixel
    ridges on its two curbs (rows 40 and 79, the roadway's first and last rows)."""
    surface = np.full((H, W), surface_outside, np.float32)
    surface[TOP:BOTTOM] = surface_inside
    boundary = np.zeros((H, W), np.float32)
    boundary[[TOP, BOTTOM - 1]] = 0.9
    return surface, boundary


def afanet_graph() -> BoundaryGraph:
    """One edge along the top curb, broken into a zigzag that misses it by 3 px, and one far
    from the street (a roof outline)."""
    line = np.array([[20.5, 40.5], [80.5, 43.5], [140.5, 40.5], [200.5, 43.5], [280.5, 40.5]])
    roof = np.array([[20.5, 110.5], [120.5, 110.5]])
    return BoundaryGraph(
        np.array([line[0], line[-1], roof[0], roof[-1]]),
        np.array([[0, 1], [2, 3]]),
        edge_kinds=["normal", "normal"],
        edge_polylines=[line, roof],
        edge_scores=np.array([0.7, 0.6]),
    )


def kinds_and_lines(graph: BoundaryGraph, kind: str) -> list[np.ndarray]:
    return [graph.edge_polyline(k) for k in range(graph.n_edges) if graph.edge_kinds[k] == kind]


def test_a_sure_street_is_framed_by_its_two_curbs():
    surface, boundary = street()
    fused = fused_with_outline(afanet_graph(), surface, boundary, OutlineConfig(sure=0.8))
    outlines = kinds_and_lines(fused, OUTLINE)
    rows = np.concatenate([line[:, 1] for line in outlines])
    assert np.all((np.abs(rows - 40.5) <= 1.0) | (np.abs(rows - 79.5) <= 1.0))  # on the two curbs, to the pixel
    for curb in (40.5, 79.5):  # each curb is drawn along the street's length (the outline runs to the window's sides)
        xs = np.concatenate([line[np.abs(line[:, 1] - curb) <= 1.0, 0] for line in outlines])
        assert xs.min() < 10 and xs.max() > W - 10
    assert len(kinds_and_lines(fused, "normal")) == 1  # the zigzag along the curb is gone; the roof edge stays
    assert np.array_equal(kinds_and_lines(fused, "normal")[0], afanet_graph().edge_polyline(1))


@pytest.mark.parametrize("inside, outside, support", [(0.6, 0.4, 0.9), (1.0, 0.0, 0.0)])
def test_nothing_changes_where_the_surface_is_unsure_or_the_boundary_map_disagrees(inside, outside, support):
    surface, boundary = street(inside, outside)
    boundary *= support
    graph = afanet_graph()
    assert fused_with_outline(graph, surface, boundary, OutlineConfig(sure=0.8)) is graph


def test_off_by_default():
    surface, boundary = street()
    graph = afanet_graph()
    assert not OutlineConfig().active
    assert fused_with_outline(graph, surface, boundary, OutlineConfig()) is graph


def test_outline_pixels_are_added_only_inside_the_region_but_edges_are_cut_everywhere():
    surface, boundary = street()
    fused = fused_with_outline(afanet_graph(), surface, boundary, OutlineConfig(sure=0.8), region=(0, H, 0, 150))
    xs = np.concatenate([line[:, 0] for line in kinds_and_lines(fused, OUTLINE)])
    assert xs.max() <= 150.5
    assert len(kinds_and_lines(fused, "normal")) == 1  # the curb edge was cut on the whole window


def test_an_edge_is_cut_where_it_runs_along_the_mask():
    graph = BoundaryGraph(
        np.array([[0.5, 10.5], [100.5, 10.5]]),
        np.array([[0, 1]]),
        edge_kinds=["normal"],
        edge_polylines=[np.array([[0.5, 10.5], [100.5, 10.5]])],
        edge_scores=np.array([0.5]),
    )
    mask = np.zeros((30, 120), bool)
    mask[12, 40:61] = True  # 1.5 px from the edge, from x 40 to 60
    cut = cut_along(graph, mask, OutlineConfig(sure=0.5, cover_px=8.0, keep_px=20.0))
    assert cut.n_edges == 2
    spans = sorted((line[:, 0].min(), line[:, 0].max()) for line in (cut.edge_polyline(0), cut.edge_polyline(1)))
    # the points within 8 px of the mask are those with 32.4 < x < 68.6 (sqrt(8^2 - 1.5^2) = 7.86 beyond each end), every 2 px
    assert spans[0][0] == 0.5 and 30 <= spans[0][1] <= 33
    assert 68 <= spans[1][0] <= 71 and spans[1][1] == 100.5
    assert cut.vertex_kinds[2:] == ["cut", "cut"]
    short = cut_along(graph, mask, OutlineConfig(sure=0.5, cover_px=8.0, keep_px=40.0))
    assert short.n_edges == 0  # both pieces under 40 px


def test_short_unsure_stretches_between_kept_ones_are_bridged():
    outline = np.zeros((10, 100), bool)
    outline[5, :] = True
    kept = outline.copy()
    kept[5, 40:60] = False  # 20 px unsure
    assert bridged(outline, kept, 60.0)[5].all()
    assert not bridged(outline, kept, 10.0)[5, 40:60].any()
    end = outline.copy()
    end[5, 80:] = False  # an unsure end touches one kept stretch only: not a bridge
    assert not bridged(outline, end, 60.0)[5, 80:].any()


def test_points_move_onto_the_ridge_and_the_ends_stay():
    boundary = np.zeros((40, 100), np.float32)
    boundary[23] = 0.8  # ridge through pixel centres y = 23.5
    line = np.array([[10.5, 20.5], [90.5, 20.5]])
    placed = placed_on_ridge(line, boundary, OutlineConfig(sure=0.5, place_px=4.0, simplify_px=0.5))
    assert np.array_equal(placed[0], line[0]) and np.array_equal(placed[-1], line[-1])
    assert np.allclose(
        np.interp([20.5, 50.5, 80.5], placed[:, 0], placed[:, 1]), 23.5
    )  # the median keeps the moves whole
    far = placed_on_ridge(line, boundary, OutlineConfig(sure=0.5, place_px=2.0, simplify_px=0.5))
    assert np.allclose(far[:, 1], 20.5)  # the ridge is 3 px away: out of reach


def test_a_surface_map_unsure_around_the_street_frames_nothing():
    surface, boundary = street(
        surface_outside=0.35
    )  # lawns and roofs half called roadway: about half of every square unsure
    graph = afanet_graph()
    assert fused_with_outline(graph, surface, boundary, OutlineConfig(sure=0.3, max_unsure=0.3)) is graph
    assert fused_with_outline(graph, surface, boundary, OutlineConfig(sure=0.3, max_unsure=1.0)) is not graph


def test_two_windows_cut_the_outline_at_the_same_point_of_their_seam():
    """A diagonal street across a mosaic seen by two overlapping windows (columns 0-199 and
    100-299, cores meeting at x = 150): both trace the same outline pixels there, so the ends
    they leave on the seam coincide."""
    h, w = 160, 300
    rows, cols = np.mgrid[0:h, 0:w]
    road = np.abs(rows - (30 + 0.3 * cols)) < 20  # a street rising 0.3 px per px
    surface = road.astype(np.float32)
    inner = road & ~(np.roll(road, 1, 0) & np.roll(road, -1, 0))
    boundary = np.where(inner, 0.9, 0.0).astype(np.float32)
    config = OutlineConfig(sure=0.8)
    empty = BoundaryGraph(edge_kinds=[], edge_polylines=[], edge_scores=np.zeros(0))
    left = fused_with_outline(empty, surface[:, :200], boundary[:, :200], config, region=(0, h, 0, 151))
    right = fused_with_outline(empty, surface[:, 100:], boundary[:, 100:], config, region=(0, h, 50, 101))
    on_seam_left = left.vertices[np.isclose(left.vertices[:, 0], 150.0)]
    on_seam_right = right.vertices[np.isclose(right.vertices[:, 0], 50.0)] + [100.0, 0.0]
    assert len(on_seam_left) == 2  # both curbs cross the seam
    assert np.allclose(np.sort(on_seam_left[:, 1]), np.sort(on_seam_right[:, 1]), atol=1e-6)
    assert left.vertices[:, 0].max() <= 150.0 + 1e-9 and right.vertices[:, 0].min() >= 50.0 - 1e-9


def test_a_bundle_carries_the_outline_and_the_command_line_turns_it_off(tmp_path):
    import torch

    from csboundary.errors import InputError
    from csboundary.graph.settings import GraphOverrides, GraphSettings
    from csboundary.models.checkpoint import load_checkpoint
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor
    from helpers import fpn_without_surface_head, shipped_parts

    fpn_path, afanet_path = shipped_parts(tmp_path)
    make_bundle(fpn_path, afanet_path, tmp_path / "b.pt", GraphSettings().replaced(roadway_outline=0.65))
    predictor = PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu"))
    assert predictor.settings.outline.sure == 0.65 and predictor.reads_surface  # the maps carry the surface for it
    assert load_checkpoint(tmp_path / "b.pt", ("bundle",))["inference"]["roadway_outline"] == 0.65
    off = load_predictor(tmp_path / "b.pt", "cpu", GraphOverrides(roadway_outline=0), engine="torch")
    assert not off.settings.outline.active
    fpn_without_surface_head(fpn_path, tmp_path / "plain.pt")
    with pytest.raises(InputError, match="surface head"):
        make_bundle(
            tmp_path / "plain.pt", afanet_path, tmp_path / "no.pt", GraphSettings().replaced(roadway_outline=0.65)
        )
    make_bundle(tmp_path / "plain.pt", afanet_path, tmp_path / "plain-bundle.pt")
    with pytest.raises(InputError, match="surface head"):
        load_predictor(tmp_path / "plain-bundle.pt", "cpu", GraphOverrides(roadway_outline=0.6), engine="torch")
