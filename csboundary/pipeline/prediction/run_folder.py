"""The output folder of a prediction run, from before its work store opens to after it goes.

One run at a time works in a folder (:mod:`csboundary.data.folder_lock`): a second one is
refused before it touches anything. The work store is opened, or resumed, under the lock and
removed once the outputs are in place. A full disk ends the run in one line that says what is
left: a store holding finished work (patch maps, window graphs) is kept, since the same command
continues it once there is room, and the line says where it is and its size; a store without
work is removed, and so is the folder when this run made it and nothing else is in it.
"""

from __future__ import annotations

import contextlib
import errno
import shutil
from pathlib import Path
from typing import Iterator

from csboundary.data.atomic import check_output_dir, clear_stale_temporaries
from csboundary.data.folder_lock import folder_lock
from csboundary.pipeline.prediction.run_store import STORE_DIR, RunStore, holds_work


@contextlib.contextmanager
def run_folder(out_dir: str | Path, manifest: dict, restart: bool = False) -> Iterator[tuple[Path, RunStore]]:
    """(the output folder, made if need be; its work store for ``manifest``) for the block that
    runs the prediction; ``restart`` discards an unfinished run's store."""
    made = not Path(out_dir).exists()
    out = check_output_dir(out_dir, create=True)
    try:
        with folder_lock(out):
            clear_stale_temporaries(out)  # what a run killed with SIGKILL left behind
            store = None
            try:
                store = RunStore.open(out / STORE_DIR, manifest, restart=restart, write_behind=True)
                yield out, store
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise
                raise _full_disk(out, store) from exc
            store.remove()
    except BaseException:
        if made:
            with contextlib.suppress(OSError):
                out.rmdir()  # only when empty
        raise


def _full_disk(out: Path, store: RunStore | None) -> OSError:
    """The one-line error of a run that found the disk full, once its store is kept or removed."""
    root = out / STORE_DIR
    if store is not None:
        store.abandon()
    if root.exists() and not holds_work(root):
        shutil.rmtree(root, ignore_errors=True)
    if not root.exists():
        return OSError(errno.ENOSPC, "no space left on device; nothing of the run was kept", str(out))
    size = sum(f.stat().st_size for f in root.rglob("*") if f.is_file()) / 2**20
    return OSError(
        errno.ENOSPC,
        f"no space left on device; the finished work ({size:.1f} MB) is kept in {root}: free some space "
        "and run the same command to continue, or delete that folder",
        str(out),
    )
