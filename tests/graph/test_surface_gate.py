"""The surface gate: keypoint and boundary maps kept only where the road surface changes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph.settings import GraphOverrides
from csboundary.graph.surface_gate import SurfaceGateConfig, gated_maps, roadway_pieces_kept, surface_change


def street(h=200, w=200, top=80, bottom=120) -> np.ndarray:
    surface = np.zeros((h, w), np.float32)
    surface[top:bottom] = 1.0
    return surface


def test_the_gate_is_one_at_a_curb_and_zero_on_a_roof_and_inside_the_roadway():
    surface = street()
    gate = surface_change(surface, SurfaceGateConfig(radius_px=8, min_piece_px=0))
    assert gate[80, 100] == 1.0 and gate[79, 100] == 1.0  # either side of the curb at row 80
    assert gate[40, 100] == 0.0  # a roof 40 px from the street: no roadway within 8 px
    assert gate[100, 100] == 0.0  # the middle of the street: roadway all round
    assert gate[87, 100] == 1.0 and gate[88, 100] == 0.0  # the band reaches radius_px - 0.5 from the curb line


def test_a_partial_change_is_scaled_by_full_change():
    surface = np.full((50, 50), 0.2, np.float32)
    surface[:, 25:] = 0.5  # a change of 0.3
    gate = surface_change(surface, SurfaceGateConfig(radius_px=4, full_change=0.6, min_piece_px=0))
    assert gate[25, 25] == pytest.approx(0.5)


def test_gated_maps_multiply_keypoint_and_boundary_and_keep_the_surface():
    surface = street()
    maps = np.stack([np.full_like(surface, 0.9), np.full_like(surface, 0.8), surface])
    out = gated_maps(maps, 2, SurfaceGateConfig(radius_px=8, min_piece_px=0))
    assert out[0, 40, 100] == 0.0 and out[1, 40, 100] == 0.0
    assert out[0, 80, 100] == pytest.approx(0.9) and out[1, 80, 100] == pytest.approx(0.8)
    assert np.array_equal(out[2], surface)
    assert gated_maps(maps, 2, SurfaceGateConfig()) is maps  # off by default
    assert gated_maps(maps[:2], 2, SurfaceGateConfig(radius_px=8)) is not None  # no surface channel: unchanged
    assert np.array_equal(gated_maps(maps[:2], 2, SurfaceGateConfig(radius_px=8)), maps[:2])


def test_small_roadway_pieces_away_from_the_border_are_not_roadway():
    surface = street()
    surface[20:40, 20:40] = 1.0  # a 400 px blob (a lot the head mistook for road)
    kept = roadway_pieces_kept(surface, 0.5, min_piece_px=1000)
    assert kept[100, 100] and not kept[30, 30]  # the street touches the border: kept whatever its size
    gate = surface_change(surface, SurfaceGateConfig(radius_px=8, min_piece_px=1000))
    assert gate[20, 30] == 0.0  # no boundary around the dropped blob
    assert surface_change(surface, SurfaceGateConfig(radius_px=8, min_piece_px=0))[20, 30] == 1.0


@settings(max_examples=25, deadline=None)
@given(st.integers(10, 150), st.integers(5, 40), st.integers(2, 12))
def test_the_gate_is_nonzero_exactly_within_radius_of_a_curb(top, width, radius):
    surface = street(top=top, bottom=top + width)
    gate = surface_change(surface, SurfaceGateConfig(radius_px=radius, min_piece_px=0))
    rows = np.arange(surface.shape[0])
    distance = np.minimum(np.abs(rows - (top - 0.5)), np.abs(rows - (top + width - 0.5)))  # to the nearest curb line
    expected = distance < radius + 0.5
    assert np.array_equal(gate[:, 100] > 0, expected)


def test_a_bundle_carries_the_gate_and_the_both_sides_rule_and_the_maps_carry_the_surface(tmp_path):
    import torch

    from csboundary.errors import InputError
    from csboundary.graph.settings import GraphSettings
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor
    from helpers import fpn_without_surface_head, shipped_parts

    fpn_path, afanet_path = shipped_parts(tmp_path)
    make_bundle(
        fpn_path,
        afanet_path,
        tmp_path / "b.pt",
        GraphSettings().replaced(surface_check=0.5, surface_both_sides=0.7, surface_gate=8),
    )
    predictor = PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu"))
    assert predictor.settings.gate.radius_px == 8.0 and predictor.settings.surface.both_sides == 0.7
    # the gate alone needs the surface channel: it is carried with the check off
    gated = load_predictor(tmp_path / "b.pt", "cpu", GraphOverrides(surface_check=0), engine="torch")
    assert not gated.settings.surface.active and gated.settings.gate.active
    assert gated.maps(np.zeros((4, 128, 128), np.uint8)).shape == (3, 128, 128)
    assert not load_predictor(
        tmp_path / "b.pt", "cpu", GraphOverrides(surface_gate=0), engine="torch"
    ).settings.gate.active
    fpn_without_surface_head(fpn_path, tmp_path / "plain.pt")
    with pytest.raises(InputError, match="surface head"):
        make_bundle(tmp_path / "plain.pt", afanet_path, tmp_path / "no.pt", GraphSettings().replaced(surface_gate=8))
