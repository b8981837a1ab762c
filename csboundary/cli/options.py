"""What the commands share: option checks and parsers that turn bad values into usage errors,
output checks made before any work, and the help texts of options several commands take."""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
from pathlib import Path
from typing import Annotated, Callable, Optional, Sequence

import typer

from csboundary.errors import InputError
from csboundary.graph.settings import OPTIONS, SETTINGS, GraphOverrides

SUPPORT_HELP = "Mean boundary probability an AfANet edge needs along its length (0 = no check)."
LENGTH_HELP = "Longest AfANet edge kept, in pixels (0 = no limit)."
GAP_HELP = "Longest stretch of an AfANet edge, in pixels, where the boundary map is below the gap level (0 = no check)."
FILL_HELP = "Fill in segmentation-skeleton stretches at least this long that no edge covers, in pixels (0 = off)."
JOIN_HELP = (
    "Join two dangling ends at most this many pixels apart that head towards each other over boundary (0 = off)."
)
ATTACH_HELP = (
    "City graph: join a dangling end to the nearest line of another piece at most this many pixels ahead of it "
    "(0 = off)."
)
ATTACH_BACKED_HELP = (
    "Join a dangling end of a window's graph to the nearest line of another piece at most this many pixels ahead "
    "of it where the boundary map backs the join, as --join-ends (0 = off)."
)
FRAGMENT_HELP = "Drop connected pieces of the city graph shorter than this, in pixels (0 = keep all)."
THRESHOLD_HELP = "Adjacency probability for an edge."
ENGINE_HELP = "The networks on PyTorch or ONNX Runtime (auto: onnx on a CPU when installed)."
PRECISION_HELP = (
    "The FPN's arithmetic. auto: int8 where this CPU runs it faster "
    "than float32 on ONNX Runtime (timed once per machine and weights file), else float32. bfloat16 runs it in PyTorch "
    "under autocast: 2.5x faster on CPUs "
    "with AMX (Intel Xeon 4th generation and later), slower on CPUs without bfloat16 units. int8 runs it quantized on "
    "ONNX Runtime (CPU, onnx engine; prepared once per weights file): 2.5-2.8x faster on CPUs with VNNI or AMX. "
    "Scores move a little with either (docs/cpu-inference.md)."
)
DEVICE_HELP = "Where the networks run (auto: CUDA when present)."
WEIGHTS_HELP = "Weights bundle (default: the shipped weights)."


def finite(value: float | None) -> float | None:
    """Typer's ``min``/``max`` let NaN through (every comparison with NaN is false), and an
    infinite pixel size or threshold is never meant: refuse both with a usage error."""
    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"must be a finite number, got {value}")
    return value


def positive(value: float | None) -> float | None:
    """A pixel size: finite and above zero (0 would divide every length by zero)."""
    value = finite(value)
    if value is not None and value <= 0:
        raise typer.BadParameter(f"must be a positive pixel size, got {value}")
    return value


# Options several commands take, declared once (``name: WeightsOption = None``).
WeightsOption = Annotated[Optional[Path], typer.Option(metavar="FILE", help=WEIGHTS_HELP)]
EngineOption = Annotated[str, typer.Option(metavar="auto|torch|onnx", help=ENGINE_HELP)]
PrecisionOption = Annotated[str, typer.Option(metavar="auto|float32|bfloat16|int8", help=PRECISION_HELP)]
DeviceOption = Annotated[str, typer.Option(metavar="auto|cpu|cuda", help=DEVICE_HELP)]
QuietOption = Annotated[bool, typer.Option("--quiet", help="No progress bar.")]

SURFACE_HELP = (
    "Road-surface check: an edge needs this mean road-surface probability beside it, or a connected edge that has it "
    "(0 = off; the FPN needs a surface head)."
)
GATE_HELP = (
    "Surface gate: keypoint and boundary maps are kept only within this many pixels of a change of the road surface "
    "(roofs, lots and rows of parked cars lose their outlines; 0 = off; the FPN needs a surface head)."
)
OUTLINE_HELP = (
    "Roadway outline: where the road-surface map is at least this sure on one side and at most 1 minus it on the "
    "other, and the boundary map backs it, the roadway's outline replaces the edges along it (0 = off; the FPN needs a "
    "surface head)."
)
CONFIDENCE_HELP = (
    "Drop the city graph's edges whose confidence (the calibrated probability that an edge is a true boundary) is "
    "below this (0 = keep all; docs/confidence.md shows precision and recall against it)."
)
DEGREE_HELP = "Edges per vertex at most (0 = no limit; default: the weights', 2 = polylines)."
GRAPH_PANEL = "Graph settings (default: the weights'; bundle-weights: off)"


def _graph_option(flag: str, metavar: str, help: str, low: float = 0.0, high: float | None = None, kind: type = float):
    return Annotated[
        Optional[kind],
        typer.Option(
            flag,
            metavar=metavar,
            callback=finite if kind is float else None,
            min=low,
            max=high,
            help=help,
            rich_help_panel=GRAPH_PANEL,
        ),
    ]


# The graph options: one per field of GraphOverrides (graph/settings.py's OPTIONS), their ranges the settings'.
# Commands take them as one ``graph: GraphOverrides`` parameter through ``with_graph_options``.
GRAPH_HELP = {
    "edge_threshold": ("P", THRESHOLD_HELP),
    "min_edge_support": ("P", SUPPORT_HELP),
    "max_edge_length": ("PX", LENGTH_HELP),
    "max_edge_gap": ("PX", GAP_HELP),
    "fill_min_length": ("PX", FILL_HELP),
    "join_ends": ("PX", JOIN_HELP),
    "attach_ends": ("PX", ATTACH_HELP),
    "attach_backed": ("PX", ATTACH_BACKED_HELP),
    "surface_check": ("P", SURFACE_HELP),
    "surface_gate": ("PX", GATE_HELP),
    "roadway_outline": ("P", OUTLINE_HELP),
    "max_degree": ("N", DEGREE_HELP),
    "min_fragment_length": ("PX", FRAGMENT_HELP),
    "min_confidence": ("P", CONFIDENCE_HELP),
}
GRAPH_OPTIONS = {
    name: _graph_option(
        "--" + name.replace("_", "-"),
        metavar,
        help,
        low=SETTINGS[name].low,
        high=SETTINGS[name].high,
        kind=int if name == "max_degree" else float,
    )
    for name, (metavar, help) in GRAPH_HELP.items()
}  # the ranges: the settings' own
if tuple(GRAPH_HELP) != OPTIONS:
    raise RuntimeError("GRAPH_HELP and graph/settings.py's OPTIONS name different options")


def with_graph_options(command: Callable) -> Callable:
    """``command`` with its ``graph: GraphOverrides`` parameter shown to the command line as the
    graph options (:data:`GRAPH_OPTIONS`, one help panel) and handed back to it as one object."""
    signature = inspect.signature(command, eval_str=True)
    if set(GRAPH_OPTIONS) != {f.name for f in dataclasses.fields(GraphOverrides)}:
        raise RuntimeError("GRAPH_OPTIONS and GraphOverrides name different options")
    parameters = []
    for parameter in signature.parameters.values():
        if parameter.name == "graph":
            parameters += [
                inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=None, annotation=annotation)
                for name, annotation in GRAPH_OPTIONS.items()
            ]
        else:
            parameters.append(parameter.replace(kind=inspect.Parameter.KEYWORD_ONLY))

    @functools.wraps(command)
    def wrapper(**values):
        graph = GraphOverrides(**{name: values.pop(name) for name in GRAPH_OPTIONS})
        return command(graph=graph, **values)

    del wrapper.__wrapped__  # typer reads the signature below, not the command's
    wrapper.__signature__ = signature.replace(parameters=parameters)
    wrapper.__annotations__ = {p.name: p.annotation for p in parameters}
    return wrapper


def parse_tiles(text: str) -> tuple[int, int]:
    """``ROWSxCOLS`` such as ``2x2``, each at least 1."""
    try:
        rows, cols = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise typer.BadParameter(f"expected ROWSxCOLS such as 2x2, got {text!r}") from None
    if rows < 1 or cols < 1:
        raise typer.BadParameter(f"tiles must be at least 1x1, got {text!r}")
    return rows, cols


def parse_numbers(text: str, count: int, option: str, form: str, kind: type = float) -> list:
    """``count`` comma-separated finite numbers of ``kind`` (float or int), else a usage error
    on ``option`` showing the expected ``form``."""
    try:
        values = [kind(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise typer.BadParameter(f"expected {form}, got {text!r}", param_hint=option)
    return values


def out_dir(out: Path, inputs: Sequence[Path] = ()) -> None:
    """The output folder is checked (and made) before any work, outside every input folder."""
    from csboundary.data.atomic import check_output_dir

    check_output_dir(out, inputs=inputs)


def readable_inputs(inputs: Sequence[Path]) -> None:
    """The imagery (tiles, a folder of tiles, a city directory) is opened and closed before any
    network loads: a missing or unreadable input is reported in about a second, not after the
    seconds it takes to import PyTorch and read the weights."""
    from csboundary.data.inputs import open_imagery

    mosaic, _ = open_imagery(inputs)
    mosaic.close()


def out_file(path: Path, suffixes: tuple[str, ...]) -> None:
    """An output file is checked (name, place, writable) before any work."""
    from csboundary.data.atomic import check_output_file

    check_output_file(path, suffixes)


def no_file_at(out: Path) -> None:
    """A folder-making command whose target is an existing file."""
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
