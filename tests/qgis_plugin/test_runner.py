"""The QGIS plugin's runner, without QGIS: the csboundary command found or refused in one line,
its progress bars turned into stages and percentages, cancel that stops it (SIGTERM, then
SIGKILL) and leaves a predict run that the same command continues."""

from __future__ import annotations

import json
import os
import stat
import sys
import time
from pathlib import Path

import pytest

from csboundary.qgis_plugin.csboundary_qgis import runner  # noqa: E402

CSBOUNDARY = Path(sys.executable).parent / "csboundary"


def script(path: Path, body: str) -> str:
    """An executable Python script standing in for the csboundary command."""
    path.write_text(f"#!{sys.executable}\n{body}")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return str(path)


class Seen:
    def __init__(self, cancel_when=None):
        self.stages, self.percents, self.lines = [], [], []
        self.cancel_when, self.canceled_at = cancel_when, None

    def progress(self) -> runner.Progress:
        return runner.Progress(
            stage=self.stages.append, percent=self.on_percent, line=self.lines.append, canceled=self.canceled
        )

    def on_percent(self, value: float) -> None:
        self.percents.append(value)
        if self.cancel_when is not None and self.canceled_at is None and self.cancel_when(self):
            self.canceled_at = time.monotonic()

    def canceled(self) -> bool:
        return self.canceled_at is not None


def test_bars_become_stages_and_percentages_and_other_lines_stay_lines(tmp_path):
    fake = script(
        tmp_path / "csboundary",
        """
import sys, time
from tqdm import tqdm
print("9 patches (3x3)", flush=True)
for _ in tqdm(range(4), desc="predict patches", unit="patch", mininterval=0):
    time.sleep(0.05)
for _ in tqdm(range(2), desc="stitch graphs", unit="block", mininterval=0):
    pass
print("wrote out: graph.json")
""",
    )
    seen = Seen()
    lines = runner.run(fake, [], seen.progress())
    assert seen.stages == ["predict patches", "stitch graphs"]
    assert [p for p in seen.percents[:5]] == [0, 25, 50, 75, 100] and seen.percents[-1] == 100
    assert seen.lines == lines == ["9 patches (3x3)", "wrote out: graph.json"]


def test_a_failure_is_the_command_s_own_error_line_and_a_traceback_names_the_environment(tmp_path):
    bad_input = script(
        tmp_path / "a",
        "import sys\nprint('reading')\nprint('error: x.tif: not a raster', file=sys.stderr)\nsys.exit(2)",
    )
    with pytest.raises(runner.CommandError, match=r"^x\.tif: not a raster$"):
        runner.run(bad_input, [], Seen().progress())
    broken = script(tmp_path / "b", "import torch_that_is_not_there")
    with pytest.raises(runner.CommandError, match="environment is broken .*No module named 'torch_that_is_not_there'"):
        runner.run(broken, [], Seen().progress())


def test_the_command_is_found_checked_or_refused_in_one_line(tmp_path, monkeypatch):
    monkeypatch.delenv(runner.COMMAND_ENV, raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(runner.CommandError, match="no csboundary command found.*Processing > Providers > csboundary"):
        runner.find_command("")
    (tmp_path / "notes.txt").write_text("")
    with pytest.raises(runner.CommandError, match="notes.txt: not an executable file"):
        runner.find_command(str(tmp_path / "notes.txt"))
    monkeypatch.setenv(runner.COMMAND_ENV, str(CSBOUNDARY))
    assert runner.find_command("") == str(CSBOUNDARY)
    assert runner.check_command(runner.find_command("")).startswith("csboundary ")
    other = script(tmp_path / "python-only", "print('Python 3.11')")
    with pytest.raises(
        runner.CommandError, match="python-only: the csboundary environment is broken \\(Python 3.11\\)"
    ):
        runner.check_command(other)


def test_cancel_sends_sigterm_and_kills_a_command_that_ignores_it(tmp_path):
    polite = script(
        tmp_path / "polite",
        f"""
import signal, sys, time
def stop(*_):
    open({str(tmp_path / "cleaned")!r}, 'w').close()
    sys.exit(143)
signal.signal(signal.SIGTERM, stop)
print('started', flush=True)
while True:
    time.sleep(0.05)
""",
    )
    seen = Seen()
    seen.canceled = lambda: bool(seen.lines)  # cancel once it has said something
    started = time.monotonic()
    with pytest.raises(runner.Canceled):
        runner.run(polite, [], seen.progress())
    assert (tmp_path / "cleaned").exists() and time.monotonic() - started < 5
    stubborn = script(
        tmp_path / "stubborn",
        "import signal, time\nsignal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
        "print('started', flush=True)\nwhile True:\n    time.sleep(0.05)\n",
    )
    seen = Seen()
    seen.canceled = lambda: bool(seen.lines)
    started = time.monotonic()
    with pytest.raises(runner.Canceled):
        runner.run(stubborn, [], seen.progress(), grace=0.5)
    assert time.monotonic() - started < 3


def test_a_canceled_prediction_stops_within_5_s_and_the_same_command_continues_it(demo_run, tmp_path):
    """What the plugin's cancel does to a real run: SIGTERM once the first patch is done; the run
    store keeps it and the same command predicts only the rest."""
    tile = sorted(str(p) for p in (demo_run / "city" / "tiles").glob("*.tif"))[
        0
    ]  # one tile of the demo city: 2x2 patches
    args = ["predict", tile, "--out", str(tmp_path / "pred"), "--device", "cpu"]
    seen = Seen(cancel_when=lambda s: s.stages[-1:] == ["predict patches"] and s.percents[-1] > 0)
    with pytest.raises(runner.Canceled):
        runner.run(str(CSBOUNDARY), args, seen.progress())
    stopped = time.monotonic() - seen.canceled_at
    assert stopped < 5, f"{stopped:.1f} s from cancel to the command's end"
    assert any(line.startswith("interrupted (SIGTERM)") for line in seen.lines), seen.lines
    assert not (tmp_path / "pred" / "summary.json").exists() and (tmp_path / "pred" / ".csboundary-run").is_dir()
    again = Seen()
    runner.run(str(CSBOUNDARY), args, again.progress())
    work = json.loads((tmp_path / "pred" / "summary.json").read_text())["work"]
    assert work["patches_reused"] >= 1 and work["patches_reused"] + work["patches_predicted"] == 4, work
    assert os.path.exists(tmp_path / "pred" / "graph.json")


def test_a_stage_with_colons_is_one_stage_and_qgis_s_own_paths_stay_out_of_the_command(tmp_path, monkeypatch):
    fake = script(
        tmp_path / "csboundary",
        """
import os
from tqdm import tqdm
for _ in tqdm(range(2), desc="confidence: labelled cities", mininterval=0):
    pass
print("PYTHONPATH=" + os.environ.get("PYTHONPATH", "-"), "GDAL_DATA=" + os.environ.get("GDAL_DATA", "-"), "HOME" in os.environ)
""",
    )
    monkeypatch.setenv("PYTHONPATH", "/qgis/python")
    monkeypatch.setenv("GDAL_DATA", "/qgis/share/gdal")
    seen = Seen()
    runner.run(fake, [], seen.progress())
    assert seen.stages == ["confidence: labelled cities"] and seen.percents[-1] == 100
    assert seen.lines == ["PYTHONPATH=- GDAL_DATA=- True"]


def test_a_failing_callback_never_leaves_the_command_running(tmp_path):
    pid_file = tmp_path / "pid"
    fake = script(
        tmp_path / "csboundary",
        f"""
import os, time
open({str(pid_file)!r}, "w").write(str(os.getpid()))
print("started", flush=True)
while True:
    time.sleep(0.05)
""",
    )

    def fail(line):
        raise RuntimeError("the log window is gone")

    with pytest.raises(RuntimeError):
        runner.run(fake, [], runner.Progress(line=fail), grace=1.0)
    pid = int(pid_file.read_text())
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # gone (and reaped)


def test_the_plugin_zip_holds_the_plugin_in_one_folder_as_qgis_installs_it(tmp_path):
    import zipfile

    from csboundary.qgis_plugin import PLUGIN, plugin_version
    from helpers import run_cli

    done = run_cli("qgis-plugin", "--out", str(tmp_path / "plugin.zip"))
    assert done.returncode == 0 and f"the csboundary QGIS plugin {plugin_version()}" in done.stdout, done.stderr
    with zipfile.ZipFile(tmp_path / "plugin.zip") as archive:
        names = set(archive.namelist())
        assert names == {f"csboundary_qgis/{p.name}" for p in PLUGIN.iterdir() if p.is_file()}
        assert {"csboundary_qgis/metadata.txt", "csboundary_qgis/__init__.py", "csboundary_qgis/icon.svg"} <= names
        assert archive.read("csboundary_qgis/runner.py") == (PLUGIN / "runner.py").read_bytes()
        metadata = archive.read("csboundary_qgis/metadata.txt").decode()
    assert "qgisMinimumVersion=3.22" in metadata and "hasProcessingProvider=yes" in metadata
