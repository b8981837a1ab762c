"""Shared by several test files: running the command line, and hypothesis strategies."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from affine import Affine
from hypothesis import strategies as st


def run_cli(*args: str, cwd: Path | None = None, timeout: int = 600, preexec_fn=None) -> subprocess.CompletedProcess:
    """``python -m csboundary ARGS`` as a user runs it: exit code, stdout, stderr."""
    return subprocess.run(
        [sys.executable, "-m", "csboundary", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
        preexec_fn=preexec_fn,
    )


def obey_file_permissions() -> None:
    """A ``preexec_fn`` for a command run as root: it drops CAP_DAC_OVERRIDE (Linux), so a folder
    without write permission stops it as it stops a user (the suite may run as root)."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(24, 1, 0, 0, 0) != 0:  # PR_CAPBSET_DROP, CAP_DAC_OVERRIDE: gone from the command it execs
        raise OSError(ctypes.get_errno(), "cannot drop CAP_DAC_OVERRIDE")


north_up = st.builds(
    lambda gsd_x, gsd_y, x0, y0: Affine(gsd_x, 0.0, x0, 0.0, -gsd_y, y0),
    st.floats(0.05, 30.0),
    st.floats(0.05, 30.0),
    st.floats(-1e6, 1e6),
    st.floats(-1e7, 1e7),
)


def shipped_parts(folder: Path, **afanet_extra) -> tuple[Path, Path]:
    """The shipped bundle's FPN and AfANet written as the two checkpoints ``bundle-weights``
    takes (``folder/fpn.pt``, ``folder/afanet.pt``; ``afanet_extra`` adds fields such as a
    ``train_config``), for tests that make bundles with other inference settings."""
    from csboundary.models.checkpoint import load_checkpoint, save_checkpoint, shipped_weights

    shipped = load_checkpoint(shipped_weights(), ("bundle",))
    save_checkpoint(folder / "fpn.pt", "fpn", fpn=shipped["fpn"], fpn_config=shipped["fpn_config"])
    save_checkpoint(
        folder / "afanet.pt", "afanet", afanet=shipped["afanet"], afanet_config=shipped["afanet_config"], **afanet_extra
    )
    return folder / "fpn.pt", folder / "afanet.pt"


def fpn_without_surface_head(fpn_path: Path, out: Path) -> Path:
    """``fpn_path``'s FPN checkpoint without its road-surface head (an FPN from before the head),
    written to ``out``: for tests of what needs the surface map."""
    from csboundary.models.checkpoint import load_checkpoint, save_checkpoint

    shipped = load_checkpoint(fpn_path, ("fpn",))
    plain = {k: v for k, v in shipped["fpn"].items() if not k.startswith("surface_head.")}
    save_checkpoint(out, "fpn", fpn=plain, fpn_config={**shipped["fpn_config"], "surface": False})
    return out


def bundle_without(bundle: Path, out: Path, settings: tuple[str, ...]) -> Path:
    """A copy of ``bundle`` whose inference settings lack ``settings``: a bundle made before
    those settings existed."""
    from csboundary.models.checkpoint import load_checkpoint, save_checkpoint

    payload = load_checkpoint(bundle, ("bundle",))
    older = {k: v for k, v in payload["inference"].items() if k not in settings}
    content = {k: v for k, v in payload.items() if k not in ("format", "kind", "code_version", "inference")}
    return save_checkpoint(out, "bundle", inference=older, **content)


def square_graph():
    """Two edges of a 10 px square's corner, the second a bent polyline, scores 0.3 and 0.9; pixel
    (col, row) -> world (x, y) = (100 + 0.5 col, 200 - 0.5 row): the review edits' test graph."""
    import numpy as np

    from csboundary.graph import BoundaryGraph

    return BoundaryGraph(
        np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]),
        [[0, 1], [1, 2]],
        edge_kinds=["normal", "corner"],
        edge_polylines=[None, np.array([[10.0, 0.0], [12.0, 5.0], [10.0, 10.0]])],
        edge_scores=np.array([0.3, 0.9]),
        transform=Affine(0.5, 0, 100, 0, -0.5, 200),
        crs="EPSG:32618",
    )
