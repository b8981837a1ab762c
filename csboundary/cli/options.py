"""Checks shared by the command line's options."""

from __future__ import annotations

import math

import typer


def finite(value: float | None) -> float | None:
    """Typer's ``min``/``max`` let NaN through (every comparison with NaN is false), and an
    infinite pixel size or threshold is never meant: refuse both with a usage error."""
    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"must be a finite number, got {value}")
    return value
