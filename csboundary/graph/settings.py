"""Every setting between a window's maps and the city graph, in one frozen object.

:class:`GraphSettings` is read from a weights bundle's ``inference`` table
(:meth:`GraphSettings.from_bundle`), overridden from the command line's graph options
(:class:`GraphOverrides`, :meth:`GraphSettings.overridden`) and handed as it is to the patch
steps (vertex extraction, AfANet's decoding, the checks after it) and to the city graph
(fragments, attachment, the confidence threshold), so no step keeps a default of its own.
Every model kind of the city pipeline (the shipped networks, the baselines, the oracle) carries
one.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

from csboundary.errors import InputError
from csboundary.graph.crossings import CrossingConfig
from csboundary.graph.edge_support import EdgeSupportConfig
from csboundary.graph.end_joining import EndJoinConfig
from csboundary.graph.outline_fusion import OutlineConfig
from csboundary.graph.skeleton_fill import FillConfig
from csboundary.graph.surface_check import SurfaceCheckConfig
from csboundary.graph.surface_gate import SurfaceGateConfig
from csboundary.graph.vertex_extraction import VertexConfig


@dataclass(frozen=True)
class Setting:
    """One graph setting: where it lives in :class:`GraphSettings` (a dotted field path), its range,
    the type a bundle's value is read as (None: as stored), the bundle keys it had before, and
    whether it takes whole numbers only."""

    field: str
    low: float
    high: float
    kind: type | None = float
    old_keys: tuple[str, ...] = ()
    integer: bool = False


# Every graph setting by its one name: the bundle's key and, for those the command line sets
# (:data:`OPTIONS`), the option (``join_ends`` is ``--join-ends``, ``GraphOverrides.join_ends`` and
# the bundle key ``join_ends``). Bundles written before the names agreed are read by ``old_keys``.
SETTINGS = {
    "edge_threshold": Setting("edge_threshold", 0.0, 1.0, None),
    "max_degree": Setting("max_degree", 0, 64, None, integer=True),
    "min_edge_support": Setting("support.min_support", 0.0, 1.0, None, ("min_support",)),
    "max_edge_length": Setting("support.max_length_px", 0.0, 1e6, None, ("max_length_px",)),
    "max_edge_gap": Setting("support.max_gap_px", 0.0, 1e6, None, ("max_gap_px",)),
    "edge_support_radius": Setting("support.radius_px", 0.0, 100.0, None, ("radius_px",)),
    "edge_gap_level": Setting("support.gap_level", 0.0, 1.0, None, ("gap_level",)),
    "grid_crossings": Setting("crossings.spacing_px", 0, 100000, int, ("crossing_spacing_px",), True),
    "min_fragment_length": Setting("min_fragment_px", 0.0, 1e6, float, ("min_fragment_px",)),
    "vertex_threshold": Setting("vertices.threshold", 0.01, 1.0),
    "fill_min_length": Setting("fill.min_length_px", 0.0, 1e6, float, ("fill_min_length_px",)),
    "join_ends": Setting("join.max_px", 0.0, 1e6, float, ("join_max_px",)),
    "attach_backed": Setting("join.attach_px", 0.0, 1e6, float, ("join_attach_px",)),
    "attach_ends": Setting("attach_px", 0.0, 1e6, float, ("attach_max_px",)),
    "surface_check": Setting("surface.strong", 0.0, 1.0, float, ("surface_strong",)),
    "surface_weak": Setting("surface.weak", 0.0, 1.0),
    "surface_offset": Setting("surface.offset_px", 0.0, 100.0, float, ("surface_offset_px",)),
    "surface_both_sides": Setting("surface.both_sides", 0.0, 1.0),
    "surface_gate": Setting("gate.radius_px", 0.0, 200.0, float, ("surface_gate_px",)),
    "surface_gate_full": Setting("gate.full_change", 0.01, 1.0),
    "surface_gate_min_piece": Setting("gate.min_piece_px", 0, 10**8, int, ("surface_gate_min_piece_px",), True),
    "roadway_outline": Setting("outline.sure", 0.0, 1.0, float, ("outline_sure",)),
    "outline_support": Setting("outline.support", 0.0, 1.0),
    "outline_min_length": Setting("outline.min_length_px", 0.0, 1e6, float, ("outline_min_length_px",)),
    "outline_max_unsure": Setting("outline.max_unsure", 0.0, 1.0),
    "min_confidence": Setting("min_confidence", 0.0, 1.0),
}
BUNDLE_SETTINGS = tuple(name for name in SETTINGS if name != "min_confidence")
OLD_KEYS = {old: name for name, setting in SETTINGS.items() for old in setting.old_keys}


def setting_value(settings: "GraphSettings", name: str):
    """The value of the setting ``name`` (a key of :data:`SETTINGS`) in ``settings``."""
    value = settings
    for part in SETTINGS[name].field.split("."):
        value = getattr(value, part)
    return value


def with_setting(settings, path: str, value):
    """``settings`` (a frozen dataclass) with the field at the dotted ``path`` replaced."""
    head, _, rest = path.partition(".")
    if rest:
        value = with_setting(getattr(settings, head), rest, value)
    return dataclasses.replace(settings, **{head: value})


@dataclass(frozen=True)
class GraphOverrides:
    """The command line's graph options, by their option names (``--edge-threshold`` is
    ``edge_threshold``, the names of :data:`SETTINGS`); None keeps the bundle's value.
    ``max_degree`` 0 means no cap. A value outside its range (:data:`SETTINGS`), NaN or infinite is
    refused with the one line the command line gives."""

    edge_threshold: float | None = None
    min_edge_support: float | None = None
    max_edge_length: float | None = None
    max_edge_gap: float | None = None
    fill_min_length: float | None = None
    join_ends: float | None = None
    attach_ends: float | None = None
    attach_backed: float | None = None
    surface_check: float | None = None
    surface_gate: float | None = None
    roadway_outline: float | None = None
    max_degree: int | None = None
    min_fragment_length: float | None = None
    min_confidence: float | None = None

    def __post_init__(self) -> None:
        for name in OPTIONS:
            value, low, high = getattr(self, name), SETTINGS[name].low, SETTINGS[name].high
            if value is None:
                continue
            flag = "--" + name.replace("_", "-")
            if name == "max_degree":
                if isinstance(value, bool) or not isinstance(value, int) or value < low:
                    raise InputError(flag, f"must be a whole number >= {low}, got {value!r}")
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InputError(flag, f"must be a finite number, got {value!r}")
            if value < low or (high is not None and value > high):
                raise InputError(flag, f"must be from {low:g} to {high:g}, got {value:g}")


# the settings the command line's graph options set (--NAME), in the help's order; min_confidence
# is chosen when predicting and never stored in a bundle
OPTIONS = tuple(f.name for f in dataclasses.fields(GraphOverrides))


@dataclass(frozen=True)
class GraphSettings:
    """From a patch's maps to the city graph. The patch steps: ``vertices`` (keypoint
    extraction), ``edge_threshold`` and ``max_degree`` (AfANet's decoding), ``support`` (AfANet
    edges the boundary map must back), ``crossings`` (extra vertices on the grid lines), ``fill``
    (boundary the graph missed, from the segmentation skeleton), ``surface`` (edges need roadway
    beside them), ``join`` (dangling ends joined across supported gaps), ``gate`` (keypoint and
    boundary maps only where the surface changes), ``outline`` (the roadway's sure outline in place
    of the edges along it, :mod:`csboundary.graph.outline_fusion`). The city graph: ``min_fragment_px``
    (connected pieces shorter than this are dropped), ``attach_px`` (dangling ends joined to the
    line ahead within this), ``min_confidence`` (edges less sure than this are dropped). The
    defaults leave every optional step off."""

    vertices: VertexConfig = field(default_factory=VertexConfig)
    edge_threshold: float = 0.5
    max_degree: int | None = 2
    support: EdgeSupportConfig = field(default_factory=EdgeSupportConfig)
    crossings: CrossingConfig = field(default_factory=CrossingConfig)
    fill: FillConfig = field(default_factory=FillConfig)
    surface: SurfaceCheckConfig = field(default_factory=SurfaceCheckConfig)
    join: EndJoinConfig = field(default_factory=EndJoinConfig)
    gate: SurfaceGateConfig = field(default_factory=SurfaceGateConfig)
    outline: OutlineConfig = field(default_factory=OutlineConfig)
    min_fragment_px: float = 0.0
    attach_px: float = 0.0
    min_confidence: float = 0.0

    @property
    def reads_surface(self) -> bool:
        """Whether a step reads the FPN's road-surface map (the check, the gate or the outline)."""
        return self.surface.active or self.gate.active or self.outline.active

    @classmethod
    def from_bundle(cls, table, path: str | Path) -> "GraphSettings":
        """A bundle's ``inference`` table, checked (:func:`checked_inference_settings`); what it
        leaves out takes the defaults."""
        settings = cls()
        for name, value in checked_inference_settings(table, path).items():
            kind = SETTINGS[name].kind
            settings = with_setting(settings, SETTINGS[name].field, value if kind is None else kind(value))
        return settings

    def to_bundle(self) -> dict:
        """The ``inference`` table of a bundle that holds these settings (every one, by its name)."""
        return {name: setting_value(self, name) for name in BUNDLE_SETTINGS}

    def replaced(self, **values) -> "GraphSettings":
        """These settings with ``values`` given by setting name (``join_ends=40``)."""
        settings = self
        for name, value in values.items():
            if name not in SETTINGS:
                raise TypeError(f"unknown graph setting {name!r}")
            settings = with_setting(settings, SETTINGS[name].field, value)
        return settings

    def overridden(self, options: GraphOverrides) -> "GraphSettings":
        """These settings with the command line's ``options`` in place of the bundle's."""
        given = {name: getattr(options, name) for name in OPTIONS if getattr(options, name) is not None}
        return self.replaced(
            **{name: (value or None) if name == "max_degree" else float(value) for name, value in given.items()}
        )


def checked_inference_settings(table, path: str | Path) -> dict:
    """A bundle's inference settings by their names (an old key read as its setting), checked: an
    edge threshold of 7 or a degree cap of -1 would silently drop every edge, so an out-of-range
    or unknown value is an InputError naming the file."""
    if not isinstance(table, dict):
        raise InputError(path, "damaged weights file: 'inference' is not a table of settings")
    settings = {}
    for key, value in table.items():
        name = OLD_KEYS.get(key, key)
        if name not in BUNDLE_SETTINGS:
            raise InputError(path, f"unknown inference setting {key!r} (known: {', '.join(BUNDLE_SETTINGS)})")
        if name in settings:
            raise InputError(path, f"inference setting {name} is given twice (as {key!r} too)")
        setting = SETTINGS[name]
        settings[name] = value
        if name == "max_degree" and value is None:
            continue
        ok = (
            isinstance(value, (int, float))
            and not isinstance(value, bool)
            and math.isfinite(value)
            and setting.low <= value <= setting.high
        )
        if not ok or (setting.integer and int(value) != value):
            kind = "an integer" if setting.integer else "a number"
            raise InputError(
                path, f"inference setting {key} = {value!r} must be {kind} from {setting.low:g} to {setting.high:g}"
            )
    return settings
