"""Write files under their final name only once they are complete.

An interrupted run (Ctrl-C, crash) must never leave a half-written file that looks finished, so
every writer writes to a hidden temporary sibling and renames it into place on success.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator


@contextlib.contextmanager
def atomic_path(final: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``final``; rename it to ``final`` if the block succeeds.

    The temporary file keeps ``final``'s suffix so that format drivers keyed on the extension
    (GDAL, pyogrio) pick the right one. On any exception the temporary file is removed.
    """
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f".{final.stem}.partial-{os.getpid()}{final.suffix}")
    try:
        yield tmp
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()
