"""Shared by several test files: running the command line, and hypothesis strategies."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from affine import Affine
from hypothesis import strategies as st


def run_cli(*args: str, cwd: Path | None = None, timeout: int = 600) -> subprocess.CompletedProcess:
    """``python -m csboundary ARGS`` as a user runs it: exit code, stdout, stderr."""
    return subprocess.run([sys.executable, "-m", "csboundary", *args], capture_output=True, text=True, cwd=cwd, timeout=timeout)


north_up = st.builds(
    lambda gsd_x, gsd_y, x0, y0: Affine(gsd_x, 0.0, x0, 0.0, -gsd_y, y0),
    st.floats(0.05, 30.0),
    st.floats(0.05, 30.0),
    st.floats(-1e6, 1e6),
    st.floats(-1e7, 1e7),
)
