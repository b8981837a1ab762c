"""One run at a time in an output folder.

Two runs writing one folder spoil each other's work (they share its work store: one deletes a
patch's maps the other still needs), so a run holds an OS lock on ``.csboundary.lock`` in the
folder while it works, and a second run is refused in one line naming the first (its pid, host
and start time, which the holder writes into the file). The lock is ``flock``'s: the OS releases
it when its process ends however it ends (SIGKILL included), so a killed run never blocks the
next one, which locks the file the killed run left. The file is removed when the run ends.
Without ``fcntl`` (Windows) or on a filesystem without locks, runs are not locked.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import time
from pathlib import Path
from typing import Iterator

from csboundary.data.atomic import disk_full_error
from csboundary.errors import InputError

try:
    import fcntl
except ImportError:  # Windows: no flock
    fcntl = None

LOCK_FILE = ".csboundary.lock"
_held: set[str] = set()  # folders this process holds: locking one again is a no-op


@contextlib.contextmanager
def folder_lock(folder: str | Path, wait: bool = False) -> Iterator[None]:
    """Hold ``folder``'s lock for the block (the folder must exist); InputError naming the run
    that holds it, or with ``wait`` the wait until it ends (a cache both runs need). A process
    that holds it already may take it again (nested blocks)."""
    folder = Path(folder)
    key = str(folder.resolve())
    fd = None if fcntl is None or key in _held else _lock(folder / LOCK_FILE, folder, wait)
    if fd is None:
        yield
        return
    _held.add(key)
    try:
        with contextlib.suppress(OSError):  # who holds it is a courtesy to the run it refuses (a full disk may deny it)
            os.ftruncate(fd, 0)
            os.write(
                fd,
                f"pid {os.getpid()} on {socket.gethostname()}, started {time.strftime('%Y-%m-%d %H:%M:%S')}\n".encode(),
            )
        yield
    finally:
        _held.discard(key)
        with contextlib.suppress(OSError):
            (folder / LOCK_FILE).unlink()  # still locked: a run that opened the file meanwhile sees it gone
        os.close(fd)


@contextlib.contextmanager
def locked_folder(folder: str | Path, option: str = "--out") -> Iterator[None]:
    """``folder`` made if missing and held under its lock for the block: a second run writing
    into it is refused in one line (``option`` names the setting that gives another folder). A
    folder this call made is removed again when the block is refused (InputError) before
    anything but the lock file is in it."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(folder, f"is a file: it must be a folder (give {option} another path)")
    try:
        folder.mkdir(parents=True)
        made = True  # this call made it: only then may a refusal remove it
    except FileExistsError:
        made = False
    except OSError as exc:
        raise InputError(folder, f"cannot make the folder ({exc.strerror or exc})") from exc
    try:
        with folder_lock(folder):
            yield
    except InputError:
        if (
            made and folder.is_dir() and not any(p.name != LOCK_FILE for p in folder.iterdir())
        ):  # refused before anything was made
            shutil.rmtree(folder, ignore_errors=True)
        raise


def _lock(path: Path, folder: Path, wait: bool = False) -> int | None:
    """A descriptor of ``path`` locked by this process (None: the filesystem has no locks)."""
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            full = disk_full_error(exc, path)
            if full is not None:
                raise full from exc
            raise InputError(folder, f"cannot create its lock file {LOCK_FILE} ({exc.strerror or exc})") from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            raise InputError(
                folder, f"in use by another csboundary run ({holder}); wait for it to end, or write into another folder"
            ) from None
        except OSError:
            os.close(fd)
            return None
        with contextlib.suppress(FileNotFoundError):
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                return fd
        os.close(fd)  # the run that held it removed the file before this one locked it: lock the new one


def _holder(fd: int) -> str:
    """Who holds the lock, as the holder wrote it (it writes just after locking: wait a moment)."""
    for _ in range(20):
        text = os.pread(fd, 300, 0).decode(errors="replace").strip()
        if text:
            return text
        time.sleep(0.05)
    return "which has not said who it is"
