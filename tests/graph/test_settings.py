"""The graph settings: read from a bundle's table, overridden by the command line's options, one
frozen object that the city graph reads as the patch steps do."""

from __future__ import annotations

import dataclasses

import pytest

from csboundary.errors import InputError
from csboundary.graph.settings import (
    BUNDLE_SETTINGS,
    OLD_KEYS,
    OPTIONS,
    SETTINGS,
    GraphOverrides,
    GraphSettings,
    setting_value,
)


def test_an_empty_bundle_table_gives_the_defaults_with_every_optional_step_off():
    settings = GraphSettings.from_bundle({}, "b.pt")
    assert settings == GraphSettings()
    assert (settings.edge_threshold, settings.max_degree, settings.vertices.threshold) == (0.5, 2, 0.5)
    assert not (settings.fill.active or settings.join.active or settings.surface.active or settings.gate.active)
    assert (settings.min_fragment_px, settings.attach_px, settings.min_confidence) == (0.0, 0.0, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.edge_threshold = 0.1


def test_a_bundle_table_from_before_the_names_agreed_lands_in_its_fields():
    table = {
        "edge_threshold": 0.4,
        "max_degree": None,
        "min_support": 0.2,
        "max_length_px": 300,
        "max_gap_px": 40,
        "gap_level": 0.25,
        "crossing_spacing_px": 250,
        "min_fragment_px": 240,
        "vertex_threshold": 0.25,
        "fill_min_length_px": 40,
        "join_max_px": 30,
        "join_attach_px": 60,
        "attach_max_px": 50,
        "surface_strong": 0.5,
        "surface_weak": 0.2,
        "surface_offset_px": 8,
        "surface_both_sides": 0.7,
        "surface_gate_px": 8,
        "surface_gate_full": 0.5,
        "surface_gate_min_piece_px": 100,
        "outline_sure": 0.7,
        "outline_support": 0.4,
        "outline_min_length_px": 60,
        "outline_max_unsure": 0.2,
    }
    s = GraphSettings.from_bundle(table, "b.pt")
    assert (s.edge_threshold, s.max_degree, s.vertices.threshold, s.crossings.spacing_px) == (0.4, None, 0.25, 250)
    assert (s.support.min_support, s.support.max_length_px, s.support.max_gap_px, s.support.gap_level) == (
        0.2,
        300,
        40,
        0.25,
    )
    assert (s.fill.min_length_px, s.join.max_px, s.join.attach_px, s.attach_px, s.min_fragment_px) == (
        40,
        30,
        60,
        50,
        240,
    )
    assert (s.surface.strong, s.surface.weak, s.surface.offset_px, s.surface.both_sides) == (0.5, 0.2, 8, 0.7)
    assert (s.gate.radius_px, s.gate.full_change, s.gate.min_piece_px) == (8, 0.5, 100) and s.reads_surface
    assert (s.outline.sure, s.outline.support, s.outline.min_length_px, s.outline.max_unsure) == (0.7, 0.4, 60, 0.2)
    # the same table by the settings' names reads the same, and writing it back gives those names
    renamed = {OLD_KEYS.get(key, key): value for key, value in table.items()}
    assert GraphSettings.from_bundle(renamed, "b.pt") == s
    assert GraphSettings.from_bundle(s.to_bundle(), "b.pt") == s
    assert set(s.to_bundle()) == set(BUNDLE_SETTINGS) and {k for k in renamed if k not in BUNDLE_SETTINGS} == set()


def test_one_name_per_setting_for_the_bundle_the_option_and_the_override():
    assert set(OPTIONS) == {f.name for f in dataclasses.fields(GraphOverrides)} and set(OPTIONS) <= set(SETTINGS)
    # every setting's field path exists, and replacing it by name changes that field alone
    base = GraphSettings()
    for name, setting in SETTINGS.items():
        value = 3 if setting.integer else 0.75
        changed = base.replaced(**{name: value})
        assert setting_value(changed, name) == value, name
        assert [n for n in SETTINGS if setting_value(changed, n) != setting_value(base, n)] == [name]
    assert not set(OLD_KEYS) & set(SETTINGS)  # an old key never names another setting
    with pytest.raises(TypeError, match="unknown graph setting"):
        base.replaced(join_max_px=3)


def test_a_setting_given_by_its_old_and_new_key_is_refused():
    with pytest.raises(InputError, match="join_ends is given twice"):
        GraphSettings.from_bundle({"join_max_px": 30, "join_ends": 40}, "b.pt")


@pytest.mark.parametrize(
    "table, needle",
    [
        ({"edge_threshold": 7}, "edge_threshold = 7"),
        ({"max_degree": -1}, "max_degree = -1"),
        ({"max_degree": 2.5}, "must be an integer"),
        ({"nonsense": 1}, "unknown inference setting"),
        ({"min_support": float("nan")}, "min_support = nan"),
        ([1, 2], "not a table"),
    ],
)
def test_a_damaged_table_names_the_file(table, needle):
    with pytest.raises(InputError, match=needle) as caught:
        GraphSettings.from_bundle(table, "weights.pt")
    assert str(caught.value).startswith("weights.pt: ")


def test_each_override_replaces_its_field_and_nothing_else():
    base = GraphSettings.from_bundle(
        {"min_support": 0.2, "max_length_px": 300, "join_max_px": 30, "surface_strong": 0.5}, "b.pt"
    )
    assert base.overridden(GraphOverrides()) == base
    cases = {
        "edge_threshold": (0.3, lambda s: s.edge_threshold),
        "min_edge_support": (0.4, lambda s: s.support.min_support),
        "max_edge_length": (10, lambda s: s.support.max_length_px),
        "max_edge_gap": (5, lambda s: s.support.max_gap_px),
        "fill_min_length": (20, lambda s: s.fill.min_length_px),
        "join_ends": (0, lambda s: s.join.max_px),
        "attach_ends": (25, lambda s: s.attach_px),
        "attach_backed": (60, lambda s: s.join.attach_px),
        "surface_check": (0, lambda s: s.surface.strong),
        "surface_gate": (8, lambda s: s.gate.radius_px),
        "roadway_outline": (0.7, lambda s: s.outline.sure),
        "max_degree": (3, lambda s: s.max_degree),
        "min_fragment_length": (120, lambda s: s.min_fragment_px),
        "min_confidence": (0.6, lambda s: s.min_confidence),
    }
    assert set(cases) == {f.name for f in dataclasses.fields(GraphOverrides)}
    for name, (value, read) in cases.items():
        changed = base.overridden(GraphOverrides(**{name: value}))
        assert read(changed) == value and type(read(changed)) is (int if name == "max_degree" else float), name
        differing = [
            f.name for f in dataclasses.fields(GraphSettings) if getattr(changed, f.name) != getattr(base, f.name)
        ]
        assert len(differing) == 1, (name, differing)
    assert base.overridden(GraphOverrides(max_degree=0)).max_degree is None  # 0: no cap
    assert (
        base.overridden(GraphOverrides(min_edge_support=0.1)).support.max_length_px == 300
    )  # the rest of the check kept
