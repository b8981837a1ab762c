"""Write files under their final name only once they are complete.

An interrupted run (Ctrl-C, crash) must never leave a half-written file that looks finished, so
every writer writes to a hidden temporary sibling and renames it into place on success.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import zipfile
from pathlib import Path
from typing import Iterator, Sequence

from csboundary.errors import InputError

# Hidden temporaries of this module and of the map writer: ".<stem>.partial-<pid>..." and
# ".<stem>.scratch-<pid>...". A run killed with SIGKILL leaves them; the next run clears them.
TEMPORARY = re.compile(r"^\.[^/]*\.(partial|scratch)-(\d+)")


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
    except DiskFull:
        raise  # already names its file
    except Exception as exc:  # GDAL, pyogrio, lanelet2 and libpng fail on a full disk with their own types
        full = disk_full_error(exc, final)
        if full is not None:
            raise full from exc
        raise
    finally:
        if tmp.exists():
            tmp.unlink()


FREE_BYTES_LOW = 2**20  # less than this free after a failed write: the disk is full
NEVER_DISK = (InputError, TypeError, ValueError, KeyError, IndexError, AttributeError, NameError, AssertionError)
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
# how writers say it without an errno: the OS, SQLite (GeoPackage), GDAL's GTiff, numpy's short write
FULL_WORDS = ("no space left on device", "disk is full", "disk quota exceeded", "free disk space available")


class DiskFull(OSError):
    """ENOSPC met while writing the output file ``filename`` (its name, not its folder's)."""


def is_disk_full(exc: BaseException, folder: str | Path | None = None) -> bool:
    """Whether a failed write met a full disk: said by an errno or in words by ``exc`` or an
    error it came from (GDAL's own messages often say only "Write failed" or "Failed to commit
    transaction"), or, when ``folder`` is given, less than :data:`FREE_BYTES_LOW` is free there."""
    seen = exc
    for _ in range(8):  # the error and the ones it was raised from, as far as it matters
        if seen is None:
            break
        text = str(seen).lower()
        if (
            (isinstance(seen, OSError) and seen.errno in FULL_ERRNOS)
            or any(word in text for word in FULL_WORDS)
            or ("requested" in text and "written" in text)
        ):
            return True
        seen = seen.__cause__ or seen.__context__
    if folder is None or isinstance(exc, NEVER_DISK):  # a bad input or a bug is not a full disk, however little is free
        return False
    try:
        return shutil.disk_usage(folder).free < FREE_BYTES_LOW
    except OSError:
        return False


def disk_full_error(exc: BaseException, path: str | Path) -> OSError | None:
    """The error to show when writing ``path`` failed on a full disk: ENOSPC naming the folder
    (numpy, GDAL and others report a short write in their own words, naming no file); None when
    the failure was something else."""
    folder = Path(path).parent
    return OSError(errno.ENOSPC, "no space left on device", str(folder)) if is_disk_full(exc, folder) else None


@contextlib.contextmanager
def naming_full_disk(path: str | Path) -> Iterator[None]:
    """Around the writes of one output file: a full disk met there becomes a :class:`DiskFull`
    naming ``path``, so the user learns which file could not be written, whatever the writer
    raised; other errors pass unchanged."""
    try:
        yield
    except DiskFull:
        raise
    except Exception as exc:
        if not is_disk_full(exc, Path(path).parent):
            raise
        raise DiskFull(errno.ENOSPC, "no space left on device", str(path)) from exc


def disk_full_file(exc: BaseException | None) -> DiskFull | None:
    """The :class:`DiskFull` that ``exc`` was raised from (or is), if any: which file a run that
    ended on a full disk was writing."""
    for _ in range(8):
        if exc is None or isinstance(exc, DiskFull):
            return exc
        exc = exc.__cause__ or exc.__context__
    return None


def check_output_dir(path: str | Path, create: bool = False, inputs: Sequence[str | Path] = ()) -> Path:
    """Check that outputs can be written into the folder ``path`` before any work is done (a run
    of hours must not learn at the end that it cannot write); ``create`` makes it. The folder
    must not lie inside one of the ``inputs`` folders, where the next run would read its outputs
    (maps.tif) as imagery. Raises InputError naming the folder. Without ``create`` nothing is
    left on disk."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(path, "exists and is not a folder (choose a folder for the outputs)")
    resolved = path.resolve()
    for item in map(Path, inputs):
        if item.is_dir() and (resolved == item.resolve() or item.resolve() in resolved.parents):
            raise InputError(path, f"is inside the input folder {item}; its outputs would be read as imagery next time")
    if create:
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(path, f"cannot create the output folder ({exc.strerror or exc})") from exc
    _probe(_writable_ancestor(path, path), path)
    return path


def check_output_file(path: str | Path, suffixes: tuple[str, ...] = ()) -> Path:
    """Check that a file can be written at ``path``: not a folder, one of ``suffixes`` when given,
    not an existing file of another kind where a bundle or a zip goes (:data:`ZIP_SUFFIXES`), in
    a writable place (its folder may not exist yet). Raises InputError naming the file."""
    path = Path(path)
    if path.is_dir():
        raise InputError(path, "is a folder; give a file name")
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(path, f"needs one of the extensions {', '.join(suffixes)}")
    if path.suffix.lower() in ZIP_SUFFIXES and path.is_file() and not zipfile.is_zipfile(path):
        raise InputError(
            path,
            f"exists and is not {ZIP_SUFFIXES[path.suffix.lower()]}: writing would destroy it (give another name, "
            "or move it away)",
        )
    _probe(_writable_ancestor(path.parent, path), path)
    return path


# outputs that are zip archives (a PyTorch checkpoint is one): an existing file of that name that
# is not a zip was not written by csboundary, and is not overwritten
ZIP_SUFFIXES = {".pt": "a weights bundle", ".zip": "a zip"}


def _writable_ancestor(folder: Path, name: Path) -> Path:
    """The nearest existing folder at or above ``folder`` (where writing will be tried)."""
    existing = folder
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(name, f"cannot be written: {existing} is a file")
    return existing


def _probe(folder: Path, name: Path) -> None:
    probe = folder / f".write-probe.partial-{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise InputError(name, f"cannot write there ({exc.strerror or exc})") from exc


def clear_stale_temporaries(folder: str | Path) -> list[Path]:
    """Remove the hidden temporaries that killed runs (SIGKILL, power loss) left in ``folder``;
    files of a process that is still running are kept. Returns what was removed."""
    removed = []
    folder = Path(folder)
    if not folder.is_dir():
        return removed
    for item in folder.iterdir():
        match = TEMPORARY.match(item.name)
        if match and not _alive(int(match.group(2))):
            if item.is_dir():
                shutil.rmtree(item, ignore_errors=True)
            else:
                item.unlink(missing_ok=True)
            removed.append(item)
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextlib.contextmanager
def staging_folder(out: Path, last: str = "summary.json"):
    """A hidden folder in ``out`` that the run writes every output into; on success each file is
    moved to its final name (``last`` last), on any exception or signal the folder is
    removed: an interrupted run never leaves a file under a final name."""
    stage = out / f".run.partial-{os.getpid()}"
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    try:
        yield stage
        names = sorted((p.name for p in stage.iterdir()), key=lambda name: name == last)
        for name in names:
            os.replace(stage / name, out / name)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
