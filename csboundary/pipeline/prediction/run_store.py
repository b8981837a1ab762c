"""The persisted state of a city run: what makes ``predict`` resumable and shareable by workers.

A run has two kinds of per-patch work (paper Algorithm 1): the FPN's maps of each patch, and the
graph of each window, which needs the maps of the window's patch and of all its neighbours (to
average the overlaps). The store keeps both as one file per patch, each written under a
temporary name and renamed into place, so a file that exists is complete whatever killed the
process (SIGKILL included) and the files themselves are the progress record:

* ``maps/R_C.npy``: the patch's FPN maps (float16, as the averaging stores them), or
  ``maps/R_C.empty`` when the window has no valid pixel (the FPN was not run);
* ``graphs/R_C.npz``: the window's graph in mosaic pixels (arrays only, read without pickle);
* ``images/R_C.npy``: the patch's image as the FPN read it, until its window is connected (AfANet
  needs it a patch row later; reading it again from a city of small tiles costs ~4x more);
* ``thumbs/R_C.npy``: the patch core's pixels reduced for ``overview.png`` (bands + validity), so
  the overview needs no second pass over the imagery;
* ``cores/R_C.npy``: the stitched maps of the patch core as uint8 (with ``--write-maps`` or an
  edge confidence), or ``cores/R_C.empty`` when they are all zero;
* ``checksums/<folder>/<name>.crc``: each array file's size and CRC-32, written before the file
  is renamed into place; a resumed run checks every file against it and computes a damaged one
  again (:meth:`RunStore.verify`).

Writing a patch's maps (4.8 MB) costs about as much as stitching a window, so a store made with
``write_behind`` writes them in a background thread while the next patch is predicted; until a
file is in place its maps are served from memory (a killed run loses those few patches' maps,
which the next run predicts again). A patch's maps are deleted as soon as every window that reads them has its graph, so the disk
holds about two rows of patches, not the city. ``manifest.json`` records what the work depends
on (inputs, weights, settings, code version); a later run with a different manifest is refused
instead of mixing the two. The same store lives in memory (``root=None``) for runs that need not
survive their process (evaluation, tests).
"""

from __future__ import annotations

import json
import os
import shutil
import warnings
import zlib
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from csboundary.data.atomic import disk_full_error
from csboundary.errors import InputError, InputWarning
from csboundary.graph import BoundaryGraph
from csboundary.graph.graph_arrays import graph_arrays, graph_from_arrays
from csboundary.pipeline.prediction.float16 import to_float16

MANIFEST = "manifest.json"
STORE_DIR = ".csboundary-run"  # inside the output folder
FORMAT = "csboundary-run-store"
VERSION = 1
MAX_PENDING_WRITES = 8  # maps waiting for the background writer at most (then saving waits)

Index = tuple[int, int]


class RunMismatch(InputError):
    """The output folder holds an unfinished run of other inputs, weights or settings."""


def _stem(index: Index) -> str:
    return f"{index[0]}_{index[1]}"


def _index(stem: str) -> Index:
    row, col = stem.split("_")
    return int(row), int(col)


def _checksum_path(path: Path) -> Path:
    """Where a stored file's size and CRC-32 are kept (``checksums/<folder>/<name>.crc``)."""
    return path.parent.parent / "checksums" / path.parent.name / f"{path.name}.crc"


def _file_crc(path: Path) -> tuple[int, int]:
    """(size in bytes, CRC-32) of a file."""
    crc, size = 0, 0
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            crc, size = zlib.crc32(chunk, crc), size + len(chunk)
    return size, crc


def _atomic_save(path: Path, write, checksum: bool = False) -> None:
    """Write ``path`` under a temporary name and rename it; with ``checksum`` its size and CRC
    are recorded first (checksums/), so a resumed run can tell a damaged file from a good one."""
    tmp = path.with_name(f".{path.name}.partial-{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            write(f)
        if checksum:
            size, crc = _file_crc(tmp)
            record = _checksum_path(path)
            record.parent.mkdir(parents=True, exist_ok=True)
            _atomic_save(record, lambda f: f.write(f"{size} {crc}\n".encode()))
        os.replace(tmp, path)
    except OSError as exc:
        full = disk_full_error(exc, path)
        if full is not None:
            raise full from exc
        raise
    finally:
        tmp.unlink(missing_ok=True)


def holds_work(root: Path) -> bool:
    """Whether a store has any patch's maps or window's graph stored."""
    return any(
        not n.startswith(".") for sub in ("maps", "graphs") if (root / sub).is_dir() for n in os.listdir(root / sub)
    )


class RunStore:
    """Per-patch maps, graphs and stitched cores of one run, on disk under ``root`` or in memory."""

    def __init__(self, root: str | Path | None = None, write_behind: bool = False):
        self.root = Path(root) if root is not None else None
        self.write_behind = write_behind and self.root is not None
        self._writer: ThreadPoolExecutor | None = None
        self._pending: dict[tuple[str, Index], tuple[np.ndarray, Future]] = {}
        self._maps: dict[Index, np.ndarray | None] = {}
        self._graphs: dict[Index, BoundaryGraph] = {}
        self._memory: dict[tuple[str, Index], np.ndarray] = {}  # thumbnails and cores of a store in memory
        self._empty_cores: set[Index] = set()  # cores whose maps are all zero, of a store in memory
        self._channels: int | None = None
        if self.root is not None:
            for sub in ("maps", "images", "thumbs", "graphs", "cores"):
                (self.root / sub).mkdir(parents=True, exist_ok=True)

    # -- opening a persistent store ------------------------------------------------------------
    def __getstate__(self) -> dict:
        """A copy for another process (a Dask worker) writes synchronously: the client must find
        a task's files in place when it learns the task is done."""
        self.flush()
        state = dict(self.__dict__)
        state.update(write_behind=False, _writer=None, _pending={})
        return state

    @classmethod
    def open(cls, root: str | Path, manifest: dict, restart: bool = False, write_behind: bool = False) -> "RunStore":
        """The store at ``root`` for a run described by ``manifest`` (JSON-ready): a new one, or
        the unfinished one left by the same run. A store of a different run is a
        :class:`RunMismatch` naming what differs, unless ``restart`` discards it."""
        root = Path(root)
        manifest = {"format": FORMAT, "version": VERSION, **json.loads(json.dumps(manifest))}
        path = root / MANIFEST
        if root.exists() and restart:
            shutil.rmtree(root)
        if path.exists():
            try:
                old = json.loads(path.read_text())
                if not isinstance(old, dict):
                    raise ValueError
            except (OSError, ValueError, UnicodeDecodeError):
                raise RunMismatch(
                    root.parent,
                    f"holds an unfinished run whose {MANIFEST} is damaged; "
                    "rerun with --restart to discard it, or choose another --out",
                ) from None
            differs = [k for k in [*manifest, *(k for k in old if k not in manifest)] if old.get(k) != manifest.get(k)]
            if differs and not holds_work(
                root
            ):  # a run that failed before any work (e.g. on a damaged input) blocks nothing
                warnings.warn(
                    f"{root.parent}: discarding an unfinished run with other {', '.join(differs)} that had done no work",
                    InputWarning,
                    stacklevel=2,
                )
                shutil.rmtree(root)
            elif differs:
                raise RunMismatch(
                    root.parent,
                    f"holds an unfinished run with other {', '.join(differs)}; "
                    "rerun with --restart to discard it, or choose another --out",
                )
        elif root.exists():
            shutil.rmtree(root)  # no manifest: a store whose creation was interrupted
        resumed = path.exists()
        store = cls(root, write_behind)
        if resumed:
            for problem in store.verify():
                warnings.warn(problem, InputWarning, stacklevel=2)
        else:
            _atomic_save(path, lambda f: f.write((json.dumps(manifest, indent=1) + "\n").encode()))
        return store

    def verify(self) -> list[str]:
        """Check every stored file of a resumed run against the size and CRC-32 recorded when it
        was written, and that it reads back (header, size, graph arrays); a damaged one is
        removed, so its work is done again, and said in the returned lines. A damaged core also
        takes its window's graph: the window is connected again and the core written anew."""
        problems = []
        for folder in ("maps", "images", "thumbs", "cores", "graphs"):
            for entry in sorted(os.scandir(self.root / folder), key=lambda e: e.name):
                if entry.name.startswith(".") or entry.name.endswith(".empty"):
                    continue
                try:
                    record = _checksum_path(Path(entry.path))
                    size, crc = (int(v) for v in record.read_text().split())
                    if _file_crc(Path(entry.path)) != (size, crc):
                        raise ValueError("checksum")
                    if folder == "graphs":
                        with np.load(entry.path, allow_pickle=False) as arrays:
                            graph_from_arrays(arrays)
                    else:
                        np.load(entry.path, mmap_mode="r", allow_pickle=False)
                    continue
                except Exception:  # numpy, zipfile and the graph reader each raise their own types for a damaged file
                    pass
                os.unlink(entry.path)
                _checksum_path(Path(entry.path)).unlink(missing_ok=True)
                problems.append(f"{entry.path}: damaged in the run store; it will be computed again")
                if folder == "cores":
                    (self.root / "graphs" / f"{entry.name.rsplit('.', 1)[0]}.npz").unlink(missing_ok=True)
        return problems

    @property
    def channels(self) -> int | None:
        """Channels of the stored maps (None until a patch's maps are stored, by any process)."""
        if self._channels is None and self.root is not None and (self.root / "channels").exists():
            self._channels = int((self.root / "channels").read_text())
        return self._channels

    def remove(self) -> None:
        """Delete the store (the run's outputs are complete)."""
        self.flush()
        if self.root is not None:
            shutil.rmtree(self.root, ignore_errors=True)

    # -- what is done --------------------------------------------------------------------------
    def maps_done(self) -> set[Index]:
        """Patches whose FPN maps are stored (or known empty)."""
        if self.root is None:
            return set(self._maps)
        pending = {index for folder, index in list(self._pending) if folder == "maps"}
        return pending | {_index(n.rsplit(".", 1)[0]) for n in os.listdir(self.root / "maps") if not n.startswith(".")}

    def empty_patches(self) -> set[Index]:
        """Patches without imagery (the FPN was not run on them)."""
        if self.root is None:
            return {i for i, m in self._maps.items() if m is None}
        return {
            _index(n[: -len(".empty")])
            for n in os.listdir(self.root / "maps")
            if n.endswith(".empty") and not n.startswith(".")
        }

    def graphs_done(self) -> set[Index]:
        if self.root is None:
            return set(self._graphs)
        return {
            _index(n[: -len(".npz")])
            for n in os.listdir(self.root / "graphs")
            if n.endswith(".npz") and not n.startswith(".")
        }

    # -- maps ----------------------------------------------------------------------------------
    def save_maps(self, index: Index, maps: np.ndarray | None) -> None:
        """Store a patch's (C, S, S) maps as float16, or ``None`` for a window without imagery."""
        if maps is not None:
            maps = to_float16(maps)
            if self.channels is None:
                self._channels = maps.shape[0]
                if self.root is not None:
                    _atomic_save(self.root / "channels", lambda f: f.write(str(self._channels).encode()))
        if self.root is None:
            self._maps[index] = maps
        elif maps is None:
            _atomic_save(self.root / "maps" / f"{_stem(index)}.empty", lambda f: None)
        else:
            self._put("maps", index, maps)

    def _put(self, folder: str, index: Index, array: np.ndarray) -> None:
        if self.root is None:
            self._memory[folder, index] = array
            return
        path = self.root / folder / f"{_stem(index)}.npy"
        if not self.write_behind:
            _atomic_save(path, lambda f: np.save(f, array, allow_pickle=False), checksum=True)
            return
        self._settle(MAX_PENDING_WRITES - 1)
        if self._writer is None:
            self._writer = ThreadPoolExecutor(1, thread_name_prefix="csboundary-store-writer")
        self._pending[folder, index] = (
            array,
            self._writer.submit(_atomic_save, path, lambda f: np.save(f, array, allow_pickle=False), True),
        )

    def _get(self, folder: str, index: Index) -> np.ndarray | None:
        """A stored array (pending or memory-mapped), None if there is none."""
        if self.root is None:
            return self._memory.get((folder, index))
        entry = self._pending.get((folder, index))  # single dict operations: safe beside the writer's user thread
        if entry is not None:
            return entry[0]
        path = self.root / folder / f"{_stem(index)}.npy"
        try:
            # copy-on-write: a writable view (PyTorch's kernels take it, pipeline/prediction/float16.py);
            # nothing is ever written back to the file
            return np.load(path, mmap_mode="c", allow_pickle=False)
        except FileNotFoundError:
            return None

    def _drop(self, folder: str, index: Index) -> None:
        if self.root is None:
            self._memory.pop((folder, index), None)
            return
        entry = self._pending.pop((folder, index), None)
        if entry is not None:
            entry[1].result()  # the write must not recreate the file after it is removed
        (self.root / folder / f"{_stem(index)}.npy").unlink(missing_ok=True)
        _checksum_path(self.root / folder / f"{_stem(index)}.npy").unlink(missing_ok=True)

    def _settle(self, keep: int = 0) -> None:
        """Forget finished background writes, waiting until at most ``keep`` are pending; a
        failed write (a full disk) raises here."""
        for key in list(self._pending):
            entry = self._pending.get(key)
            if entry is not None and (entry[1].done() or len(self._pending) > keep):
                entry[1].result()
                self._pending.pop(key, None)

    def flush(self) -> None:
        """Wait for every background write."""
        self._settle(0)

    def abandon(self) -> None:
        """Wait for every background write, failed or not (the run is ending on a failure), so
        nothing is written into the store after this."""
        for _, future in list(self._pending.values()):
            future.exception()
        self._pending.clear()

    def load_maps(self, index: Index) -> np.ndarray | None:
        """A patch's stored maps (memory-mapped on disk), ``None`` for a window without imagery."""
        if self.root is None:
            return self._maps[index]
        maps = self._get("maps", index)
        if maps is not None:
            return maps
        if (self.root / "maps" / f"{_stem(index)}.empty").exists():
            return None
        raise KeyError(f"maps of patch {index} are not in the run store")

    def drop_maps(self, index: Index) -> None:
        """Forget a patch's maps once no pending window needs them (its empty marker stays)."""
        if self.root is None:
            if self._maps.get(index) is not None:
                self._maps[index] = np.zeros((0,), np.float16)  # done, no longer held
            return
        self._drop("maps", index)

    # -- images --------------------------------------------------------------------------------
    def save_image(self, index: Index, image: np.ndarray) -> None:
        """Keep a patch's image for its window's AfANet step (on disk only: in memory it would
        grow with the city's width)."""
        if self.root is not None:
            self._put("images", index, image)

    def load_image(self, index: Index) -> np.ndarray | None:
        """The kept image, or None (not kept: read it from the imagery)."""
        return self._get("images", index)

    def drop_image(self, index: Index) -> None:
        self._drop("images", index)

    def held_map_bytes(self) -> int:
        if self.root is None:
            return sum(m.nbytes for m in self._maps.values() if m is not None)
        self._settle(len(self._pending))  # forget the writes that are done
        pending = sum(m.nbytes for (folder, _), (m, _) in list(self._pending.items()) if folder == "maps")
        return pending + sum(e.stat().st_size for e in os.scandir(self.root / "maps") if e.name.endswith(".npy"))

    # -- overview thumbnails -------------------------------------------------------------------
    def save_thumb(self, index: Index, thumb: np.ndarray) -> None:
        self._put("thumbs", index, thumb)

    def load_thumb(self, index: Index) -> np.ndarray | None:
        thumb = self._get("thumbs", index)
        return None if thumb is None else np.asarray(thumb)

    # -- graphs and cores ----------------------------------------------------------------------
    def save_graph(self, index: Index, graph: BoundaryGraph) -> None:
        if self.root is None:
            self._graphs[index] = graph
        else:
            _atomic_save(
                self.root / "graphs" / f"{_stem(index)}.npz",
                lambda f: np.savez(f, **graph_arrays(graph)),
                checksum=True,
            )

    def load_graph(self, index: Index) -> BoundaryGraph:
        if self.root is None:
            return self._graphs[index]
        with np.load(self.root / "graphs" / f"{_stem(index)}.npz", allow_pickle=False) as arrays:
            return graph_from_arrays(arrays)

    def save_core(self, index: Index, values: np.ndarray | None) -> None:
        """The stitched maps of a patch core, uint8 (for ``maps.tif`` and the edge confidence);
        None for a core whose maps are all zero (no imagery near it: a marker, not 3 MB of zeros)."""
        if (
            values is not None and self.root is not None
        ):  # in place before the window's graph is: never a graph without its core
            _atomic_save(
                self.root / "cores" / f"{_stem(index)}.npy",
                lambda f: np.save(f, values, allow_pickle=False),
                checksum=True,
            )
        elif values is not None:
            self._put("cores", index, values)
        elif self.root is None:
            self._empty_cores.add(index)
        else:
            _atomic_save(self.root / "cores" / f"{_stem(index)}.empty", lambda f: None)

    def has_core(self, index: Index) -> bool:
        """Whether a core (or its all-zero marker) is stored."""
        if self.root is None:
            return ("cores", index) in self._memory or index in self._empty_cores
        return index in self._empty_cores or any(
            (self.root / "cores" / f"{_stem(index)}{ext}").exists() for ext in (".npy", ".empty")
        )

    def drop_graph(self, index: Index) -> None:
        """Forget a window's graph (it will be connected again)."""
        if self.root is None:
            self._graphs.pop(index, None)
        else:
            (self.root / "graphs" / f"{_stem(index)}.npz").unlink(missing_ok=True)
            _checksum_path(self.root / "graphs" / f"{_stem(index)}.npz").unlink(missing_ok=True)

    def mark_empty_cores(self, indices) -> None:
        """Cores known to be all zero before the run (no imagery around them): nothing is stored."""
        self._empty_cores |= set(indices)

    def load_core(self, index: Index) -> np.ndarray | None:
        """A core's stored maps, None when they are all zero."""
        core = self._get("cores", index)
        if core is not None:
            return np.asarray(core)
        if index in self._empty_cores or (
            self.root is not None and (self.root / "cores" / f"{_stem(index)}.empty").exists()
        ):
            return None
        raise KeyError(f"stitched maps of patch {index} are not in the run store")
