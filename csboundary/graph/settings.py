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

# name -> (smallest, largest, integer) of each inference setting a bundle may carry
INFERENCE_SETTINGS = {
    "edge_threshold": (0.0, 1.0, False),
    "max_degree": (0, 64, True),
    "min_support": (0.0, 1.0, False),
    "max_length_px": (0.0, 1e6, False),
    "radius_px": (0.0, 100.0, False),
    "crossing_spacing_px": (0, 100000, True),
    "min_fragment_px": (0.0, 1e6, False),
    "vertex_threshold": (0.01, 1.0, False),
    "max_gap_px": (0.0, 1e6, False),
    "gap_level": (0.0, 1.0, False),
    "fill_min_length_px": (0.0, 1e6, False),
    "join_max_px": (0.0, 1e6, False),
    "join_attach_px": (0.0, 1e6, False),
    "attach_max_px": (0.0, 1e6, False),
    "surface_strong": (0.0, 1.0, False),
    "surface_weak": (0.0, 1.0, False),
    "surface_offset_px": (0.0, 100.0, False),
    "surface_both_sides": (0.0, 1.0, False),
    "surface_gate_px": (0.0, 200.0, False),
    "surface_gate_full": (0.01, 1.0, False),
    "surface_gate_min_piece_px": (0, 10**8, True),
    "outline_sure": (0.0, 1.0, False),
    "outline_support": (0.0, 1.0, False),
    "outline_min_length_px": (0.0, 1e6, False),
    "outline_max_unsure": (0.0, 1.0, False),
}
SUPPORT_SETTINGS = (
    "min_support",
    "max_length_px",
    "radius_px",
    "max_gap_px",
    "gap_level",
)  # bundle key = EdgeSupportConfig field
SURFACE_SETTINGS = {
    "surface_strong": "strong",
    "surface_weak": "weak",
    "surface_offset_px": "offset_px",
    "surface_both_sides": "both_sides",
}  # bundle key -> SurfaceCheckConfig field
GATE_SETTINGS = {
    "surface_gate_px": ("radius_px", float),
    "surface_gate_full": ("full_change", float),
    "surface_gate_min_piece_px": ("min_piece_px", int),
}  # bundle key -> SurfaceGateConfig field and type
OUTLINE_SETTINGS = {
    "outline_sure": "sure",
    "outline_support": "support",
    "outline_min_length_px": "min_length_px",
    "outline_max_unsure": "max_unsure",
}  # bundle key -> OutlineConfig field


# each graph option's range (low, high; None: no upper bound), checked by GraphOverrides for the
# command line and the Python API alike; the command line declares the same bounds from it
GRAPH_OVERRIDE_RANGES = {
    "edge_threshold": (0.0, 1.0),
    "min_edge_support": (0.0, 1.0),
    "max_edge_length": (0.0, None),
    "max_edge_gap": (0.0, None),
    "fill_min_length": (0.0, None),
    "join_ends": (0.0, None),
    "attach_ends": (0.0, None),
    "attach_backed": (0.0, None),
    "surface_check": (0.0, 1.0),
    "surface_gate": (0.0, 200.0),
    "roadway_outline": (0.0, 1.0),
    "max_degree": (0, None),
    "min_fragment_length": (0.0, None),
    "min_confidence": (0.0, 1.0),
}


@dataclass(frozen=True)
class GraphOverrides:
    """The command line's graph options, by their option names (``--edge-threshold`` is
    ``edge_threshold``); None keeps the bundle's value. ``max_degree`` 0 means no cap. A value
    outside its range (:data:`GRAPH_OVERRIDE_RANGES`), NaN or infinite is refused with the one line
    the command line gives."""

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
        for name, (low, high) in GRAPH_OVERRIDE_RANGES.items():
            value = getattr(self, name)
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
                raise InputError(
                    flag,
                    f"must be from {low:g} to {high:g}, got {value:g}"
                    if high is not None
                    else f"must be >= {low:g}, got {value:g}",
                )


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
    def from_bundle(cls, settings, path: str | Path) -> "GraphSettings":
        """A bundle's ``inference`` table, checked (:func:`checked_inference_settings`); what it
        leaves out takes the defaults."""
        settings = checked_inference_settings(settings, path)
        return cls(
            vertices=VertexConfig(threshold=float(settings.get("vertex_threshold", 0.5))),
            edge_threshold=settings.get("edge_threshold", 0.5),
            max_degree=settings.get("max_degree", 2),
            support=EdgeSupportConfig(**{k: settings[k] for k in SUPPORT_SETTINGS if k in settings}),
            crossings=CrossingConfig(spacing_px=int(settings.get("crossing_spacing_px", 0))),
            fill=FillConfig(min_length_px=float(settings.get("fill_min_length_px", 0.0))),
            surface=SurfaceCheckConfig(
                **{name: float(settings[key]) for key, name in SURFACE_SETTINGS.items() if key in settings}
            ),
            join=EndJoinConfig(
                max_px=float(settings.get("join_max_px", 0.0)), attach_px=float(settings.get("join_attach_px", 0.0))
            ),
            gate=SurfaceGateConfig(
                **{name: kind(settings[key]) for key, (name, kind) in GATE_SETTINGS.items() if key in settings}
            ),
            outline=OutlineConfig(
                **{name: float(settings[key]) for key, name in OUTLINE_SETTINGS.items() if key in settings}
            ),
            min_fragment_px=float(settings.get("min_fragment_px", 0.0)),
            attach_px=float(settings.get("attach_max_px", 0.0)),
        )

    def overridden(self, options: GraphOverrides) -> "GraphSettings":
        """These settings with the command line's ``options`` in place of the bundle's."""
        replace = dataclasses.replace
        options = replace(
            options,
            **{
                f.name: float(getattr(options, f.name))
                for f in dataclasses.fields(options)
                if f.name != "max_degree" and getattr(options, f.name) is not None
            },
        )
        settings = self
        if options.edge_threshold is not None:
            settings = replace(settings, edge_threshold=options.edge_threshold)
        support = {
            name: value
            for name, value in (
                ("min_support", options.min_edge_support),
                ("max_length_px", options.max_edge_length),
                ("max_gap_px", options.max_edge_gap),
            )
            if value is not None
        }
        if support:
            settings = replace(settings, support=replace(settings.support, **support))
        if options.fill_min_length is not None:
            settings = replace(settings, fill=replace(settings.fill, min_length_px=options.fill_min_length))
        join = {
            name: value
            for name, value in (("max_px", options.join_ends), ("attach_px", options.attach_backed))
            if value is not None
        }
        if join:
            settings = replace(settings, join=replace(settings.join, **join))
        if options.attach_ends is not None:
            settings = replace(settings, attach_px=options.attach_ends)
        if options.surface_check is not None:
            settings = replace(settings, surface=replace(settings.surface, strong=options.surface_check))
        if options.surface_gate is not None:
            settings = replace(settings, gate=replace(settings.gate, radius_px=options.surface_gate))
        if options.roadway_outline is not None:
            settings = replace(settings, outline=replace(settings.outline, sure=options.roadway_outline))
        if options.max_degree is not None:
            settings = replace(settings, max_degree=options.max_degree or None)
        if options.min_fragment_length is not None:
            settings = replace(settings, min_fragment_px=options.min_fragment_length)
        if options.min_confidence:
            settings = replace(settings, min_confidence=options.min_confidence)
        return settings


def checked_inference_settings(settings, path: str | Path) -> dict:
    """A bundle's inference settings, checked: an edge threshold of 7 or a degree cap of -1 would
    silently drop every edge, so an out-of-range or unknown value is an InputError naming the file."""
    if not isinstance(settings, dict):
        raise InputError(path, "damaged weights file: 'inference' is not a table of settings")
    for key, value in settings.items():
        if key not in INFERENCE_SETTINGS:
            raise InputError(path, f"unknown inference setting {key!r} (known: {', '.join(INFERENCE_SETTINGS)})")
        low, high, integer = INFERENCE_SETTINGS[key]
        if key == "max_degree" and value is None:
            continue
        ok = (
            isinstance(value, (int, float))
            and not isinstance(value, bool)
            and math.isfinite(value)
            and low <= value <= high
        )
        if not ok or (integer and int(value) != value):
            kind = "an integer" if integer else "a number"
            raise InputError(path, f"inference setting {key} = {value!r} must be {kind} from {low:g} to {high:g}")
    return settings
