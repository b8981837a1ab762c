"""What the commands share: option checks and parsers that turn bad values into usage errors,
output checks made before any work, and the help texts of options several commands take."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional, Sequence

import typer

from csboundary.errors import InputError

SUPPORT_HELP = "Mean boundary probability an AfANet edge needs along its length (0 = no check; default: the weights')."
LENGTH_HELP = "Longest AfANet edge kept, in pixels (0 = no limit; default: the weights')."
GAP_HELP = "Longest stretch of an AfANet edge, in pixels, where the boundary map is below the gap level (0 = no check; default: the weights')."
FILL_HELP = "Fill in segmentation-skeleton stretches at least this long that no edge covers, in pixels (0 = off; default: the weights')."
JOIN_HELP = "Join two dangling ends at most this many pixels apart that head towards each other over boundary (0 = off; default: the weights')."
ATTACH_HELP = ("City graph: join a dangling end to the nearest line of another piece at most this many pixels ahead of it "
               "(0 = off; default: the weights').")
ATTACH_BACKED_HELP = ("Join a dangling end of a window's graph to the nearest line of another piece at most this many pixels ahead "
                      "of it where the boundary map backs the join, as --join-ends (0 = off; default: the weights').")
FRAGMENT_HELP = "Drop connected pieces of the city graph shorter than this, in pixels (0 = keep all; default: the weights')."
THRESHOLD_HELP = "Adjacency probability for an edge (default: the weights')."
ENGINE_HELP = "auto | torch | onnx: the networks on PyTorch or ONNX Runtime (auto: onnx on a CPU when installed)."
PRECISION_HELP = ("auto | float32 | bfloat16 | int8: the FPN's arithmetic. auto (default): int8 where this CPU runs it faster "
                  "than float32 on ONNX Runtime (timed once per machine and weights file), else float32. bfloat16 runs it in PyTorch under autocast: 2.5x faster on CPUs "
                  "with AMX (Intel Xeon 4th generation and later), slower on CPUs without bfloat16 units. int8 runs it quantized on "
                  "ONNX Runtime (CPU, onnx engine; prepared once per weights file): 2.5-2.8x faster on CPUs with VNNI or AMX. "
                  "Scores move a little with either (docs/cpu-inference.md).")
DEVICE_HELP = "auto | cpu | cuda."
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
WeightsOption = Annotated[Optional[Path], typer.Option(help=WEIGHTS_HELP)]
EdgeThresholdOption = Annotated[Optional[float], typer.Option(callback=finite, min=0.0, max=1.0, help=THRESHOLD_HELP)]
EdgeSupportOption = Annotated[Optional[float], typer.Option(callback=finite, min=0.0, max=1.0, help=SUPPORT_HELP)]
EdgeLengthOption = Annotated[Optional[float], typer.Option(callback=finite, min=0.0, help=LENGTH_HELP)]
EdgeGapOption = Annotated[Optional[float], typer.Option("--max-edge-gap", callback=finite, min=0.0, help=GAP_HELP)]
SURFACE_HELP = ("Road-surface check: an edge needs this mean road-surface probability beside it, or a connected edge that has it "
                "(0 = off; default: the weights'; the FPN needs a surface head).")
SurfaceOption = Annotated[Optional[float], typer.Option("--surface-check", callback=finite, min=0.0, max=1.0, help=SURFACE_HELP)]
GATE_HELP = ("Surface gate: keypoint and boundary maps are kept only within this many pixels of a change of the road surface "
             "(roofs, lots and rows of parked cars lose their outlines; 0 = off; default: the weights'; the FPN needs a surface head).")
GateOption = Annotated[Optional[float], typer.Option("--surface-gate", callback=finite, min=0.0, max=200.0, help=GATE_HELP)]
FillOption = Annotated[Optional[float], typer.Option("--fill-min-length", callback=finite, min=0.0, help=FILL_HELP)]
JoinOption = Annotated[Optional[float], typer.Option("--join-ends", callback=finite, min=0.0, help=JOIN_HELP)]
AttachOption = Annotated[Optional[float], typer.Option("--attach-ends", callback=finite, min=0.0, help=ATTACH_HELP)]
AttachBackedOption = Annotated[Optional[float], typer.Option("--attach-backed", callback=finite, min=0.0, help=ATTACH_BACKED_HELP)]
CONFIDENCE_HELP = ("Drop the city graph's edges whose confidence (the calibrated probability that an edge is a true boundary) is "
                   "below this (0 = keep all; docs/confidence.md shows precision and recall against it).")
ConfidenceOption = Annotated[Optional[float], typer.Option("--min-confidence", callback=finite, min=0.0, max=1.0, help=CONFIDENCE_HELP)]
FragmentOption = Annotated[Optional[float], typer.Option("--min-fragment-length", callback=finite, min=0.0, help=FRAGMENT_HELP)]
EngineOption = Annotated[str, typer.Option(help=ENGINE_HELP)]
PrecisionOption = Annotated[str, typer.Option(help=PRECISION_HELP)]
DeviceOption = Annotated[str, typer.Option(help=DEVICE_HELP)]
QuietOption = Annotated[bool, typer.Option(help="No progress bar.")]


def parse_tiles(text: str) -> tuple[int, int]:
    """``ROWSxCOLS`` such as ``2x2``, each at least 1."""
    try:
        rows, cols = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise typer.BadParameter(f"expected ROWSxCOLS such as 2x2, got {text!r}")
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
