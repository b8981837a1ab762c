"""A full disk while ``predict`` writes its final files, and on a Dask worker (issue 65).

The disk fills at one write point of a real run, as each writer reports it: the OS's ENOSPC in
the middle of a file, GDAL's "Failed to commit transaction" or lanelet2's "Pugixml failed to
write the map" with no space left. Each case asserts the one ``error:`` line naming the file
(exit 1, no traceback, no "internal error"), that nothing is left under a final name, and that
the same command then finishes from the kept work."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from test_hostile_inputs import image, tiny_bundle

from helpers import run_cli

# Run as ``python fault.py KIND ARG csboundary-args...``: the disk is full from the write KIND
# describes on (each check of the free space then finds none), and the command runs as main does.
FAULT = """
import errno, io, os, shutil, sys
from pathlib import Path

kind, arg = sys.argv.pop(1), sys.argv.pop(1)
full = [False]
real_usage = shutil.disk_usage


def disk_usage(path):
    usage = real_usage(path)
    return usage._replace(free=0) if full[0] else usage


def no_space():
    full[0] = True
    return OSError(errno.ENOSPC, "No space left on device")


shutil.disk_usage = disk_usage
if kind == "file":  # ARG = name.suffix: what is still buffered when it is closed does not fit (half of it is written)
    stem, suffix = arg.rsplit(".", 1)
    real_open = io.open

    class Filling:
        def __init__(self, file):
            self._file, self._closed, self._size = file, False, 0

        def close(self):
            if not self._closed:
                self._closed = True
                self._file.close()
                os.truncate(self._file.name, max(1, self._size // 2))
                raise no_space()

        def write(self, text):
            self._size = self._file.tell() + len(text)
            return self._file.write(text)

        def __getattr__(self, name):
            return getattr(self._file, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.close()

    def filling_open(file, mode="r", *a, **k):
        opened = real_open(file, mode, *a, **k)
        name = Path(str(file)).name
        return Filling(opened) if "w" in mode and stem in name and name.endswith("." + suffix) else opened

    import builtins
    builtins.open = io.open = filling_open
elif kind == "gpkg":  # ARG = layer writes that fit; the next leaves a half-made GeoPackage
    import pyogrio
    from pyogrio.errors import DataSourceError

    real_write, room = pyogrio.write_dataframe, [int(arg)]

    def write_dataframe(*a, **k):
        room[0] -= 1
        if room[0] < 0:
            full[0] = True
            raise DataSourceError("Failed to commit transaction")
        return real_write(*a, **k)

    pyogrio.write_dataframe = write_dataframe
elif kind == "lanelet2":
    import lanelet2.io

    real_write = lanelet2.io.write

    def write(path, *a, **k):
        real_write(path, *a, **k)
        Path(path).write_bytes(Path(path).read_bytes()[:100])
        full[0] = True
        raise RuntimeError("Pugixml failed to write the map (unable to create file?)")

    lanelet2.io.write = write
from csboundary.cli import main as m

sys.argv = ["csboundary", *sys.argv[1:]]
m.main()
"""

# A Dask worker preload (``distributed.worker.preload``): the worker's disk is full for the run store.
WORKER_FULL = """
import errno
import numpy as np


def full(*a, **k):
    raise OSError(errno.ENOSPC, "No space left on device")


np.save = np.savez = full
"""


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    root = tmp_path_factory.mktemp("disk")
    (root / "fault.py").write_text(FAULT)
    (root / "worker_full.py").write_text(WORKER_FULL)
    return {"root": root, "bundle": tiny_bundle(root / "bundle.pt"), "tif": image(root / "ok.tif")}


def predict_args(world, out: Path, *extra: str) -> list[str]:
    return [
        "predict",
        str(world["tif"]),
        "--out",
        str(out),
        "--weights",
        str(world["bundle"]),
        "--device",
        "cpu",
        "--quiet",
        *extra,
    ]


def with_fault(world, kind: str, arg: str, args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(world["root"] / "fault.py"), kind, arg, *args], capture_output=True, text=True, timeout=600
    )


def last_error(done: subprocess.CompletedProcess) -> str:
    """The run failed (exit 1) on one ``error:`` line, its last, without a traceback."""
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr and "internal error" not in done.stderr, done.stderr
    errors = [line for line in done.stderr.splitlines() if line.startswith("error")]
    assert len(errors) == 1 and done.stderr.strip().splitlines()[-1] == errors[0], done.stderr
    return errors[0]


def listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize(
    "name, kind, arg, extra",
    [
        (
            "boundaries.gpkg",
            "gpkg",
            "1",
            (),
        ),  # GDAL's own error, the edges layer half-way through the GeoPackage (the JSON files:
        # atomic_path, tests/data/test_atomic.py and the previous-prediction test below)
        ("map.osm", "lanelet2", "-", ("--lanelet2",)),
    ],
)
def test_a_full_disk_while_writing_an_output_names_it_and_keeps_the_work(world, tmp_path, name, kind, arg, extra):
    out = tmp_path / "out"
    line = last_error(with_fault(world, kind, arg, predict_args(world, out, *extra)))
    assert line.startswith(f"error: {out / name}: no space left on device; the finished work ("), line
    assert f"is kept in {out / '.csboundary-run'}: free some space and run the same command to continue" in line
    assert listing(out) == [".csboundary-run"]  # no half-written file under a final name, no temporary
    again = run_cli(*predict_args(world, out, *extra))
    assert again.returncode == 0, again.stderr
    work = json.loads((out / "summary.json").read_text())["work"]
    assert work["patches_predicted"] == 0 and work["patches_reused"] == 1  # the kept work, not done again
    assert not [p for p in listing(out) if p.startswith(".")]


def test_a_full_disk_leaves_the_previous_prediction_whole(world, tmp_path, monkeypatch):
    """Outputs written again into a finished folder (apply-review's way): the error names the
    GeoPackage, not its temporary, and the old files stay as they were, with no temporary."""
    import shutil

    import pyogrio
    from pyogrio.errors import DataSourceError

    from csboundary.data.atomic import DiskFull
    from csboundary.graph import BoundaryGraph
    from csboundary.pipeline.outputs.prediction_files import write_graph_outputs

    out = tmp_path / "out"
    assert run_cli(*predict_args(world, out)).returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def full(*a, **k):
        monkeypatch.setattr(shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 10**9, 0))
        raise DataSourceError("Failed to commit transaction")

    monkeypatch.setattr(pyogrio, "write_dataframe", full)
    with pytest.raises(DiskFull) as raised:
        write_graph_outputs(BoundaryGraph.read_json(out / "graph.json"), out)
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(out / "boundaries.gpkg")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_no_space_on_a_dask_worker_ends_in_one_line(world, tmp_path):
    """The worker's store write fails: one line, no worker traceback, no retries; the same
    command, on a disk with room, then finishes (here without Dask: a run may resume on
    another cluster)."""
    out = tmp_path / "out"
    env = dict(os.environ, DASK_DISTRIBUTED__WORKER__PRELOAD=json.dumps([str(world["root"] / "worker_full.py")]))
    done = subprocess.run(
        [sys.executable, "-m", "csboundary", *predict_args(world, out, "--workers", "1")],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert last_error(done) == f"error: {out}: no space left on device; nothing of the run was kept"
    assert "Compute Failed" not in done.stderr, done.stderr
    assert not out.exists()
    again = run_cli(*predict_args(world, out))
    assert again.returncode == 0 and (out / "summary.json").exists(), again.stderr


def test_a_worker_task_returns_a_full_disk_and_raises_other_errors(tmp_path):
    """What the Dask executor calls: a full disk comes back as a value the client raises."""
    from types import SimpleNamespace

    from csboundary.pipeline.prediction.distributed import TaskFailure, predict_maps_task

    def failing(error):
        def predict_maps(batch):
            raise error

        return SimpleNamespace(threads=None, store=SimpleNamespace(root=tmp_path), predict_maps=predict_maps)

    failure = predict_maps_task(
        failing(OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "maps"))), [(0, 0)]
    )
    assert isinstance(failure, TaskFailure)
    error = failure.error()
    assert error.errno == errno.ENOSPC and error.filename == str(tmp_path / "maps")
    with pytest.raises(PermissionError):
        predict_maps_task(failing(PermissionError(errno.EACCES, "Permission denied")), [(0, 0)])


def test_a_full_disk_said_by_gdal_alone_is_one_line():
    """The command line's last resort: GDAL's or SQLite's words, no file known, no 'internal error'."""
    probe = (
        "import sys\nfrom pyogrio.errors import DataSourceError\nfrom csboundary.cli import main as m\n"
        "def boom(*a, **k):\n    raise DataSourceError('sqlite3_exec(COMMIT) failed: database or disk is full')\n"
        "m.command_line = lambda: boom\nsys.argv = ['csboundary']\nm.main()\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert last_error(done) == (
        "error: no space left on device (DataSourceError: sqlite3_exec(COMMIT) failed: database or disk is "
        "full): free some space and run the same command again"
    )
