"""Errors and warnings about user input.

Every problem with a user's file is reported as one line that names the file and the problem,
so the command line can print it verbatim and exit non-zero.
"""

from __future__ import annotations

from pathlib import Path


class InputError(Exception):
    """A user-supplied file or argument cannot be used. ``str(err)`` is ``"<path>: <problem>"``."""

    def __init__(self, path: str | Path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class InputWarning(UserWarning):
    """Input is usable only after a documented fallback (e.g. no CRS, 3-band RGB)."""


def reject_unknown(keys, allowed, what: str) -> None:
    """Configs are JSON written by hand: a misspelt key is an error, not a silent default."""
    unknown = set(keys) - set(allowed)
    if unknown:
        raise ValueError(f"unknown {what} option(s): {', '.join(sorted(unknown))}")
