"""The csboundary command of the user's environment, run for QGIS: its progress bars turned into
numbers, cancel turned into SIGTERM (the command removes its temporaries and keeps a predict
run's finished patches), its failure into one line.

QGIS's own Python seldom has PyTorch, so the plugin never imports csboundary: it runs the
command of an environment the user installed. Nothing here imports QGIS, so it is tested
without QGIS.
"""

from __future__ import annotations

import os
import queue
import re
import shutil
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

COMMAND_ENV = "CSBOUNDARY_COMMAND"  # the command's path, when the plugin's setting is empty
SETTING_PLACE = "Settings > Options > Processing > Providers > csboundary"

# a tqdm bar as csboundary prints it: "predict patches:  45%|####5     | 9/20 [00:04<00:05, 2.1patch/s]"
# A bar left open (an interrupted run) has the next message glued to its end: kept as "rest".
# A stage may hold colons ("confidence: labelled cities: 45%|...").
_BAR = re.compile(r"^\s*(?P<stage>[^|]{1,80}?):\s*(?P<percent>\d{1,3})%\|[^|]*\|[^\]]*\](?P<rest>.*)$")

# What QGIS sets for its own Python and libraries (OSGeo4W on Windows, the macOS bundle), which
# must not reach the csboundary environment's Python, GDAL and PROJ.
QGIS_ONLY = (
    "PYTHONHOME",
    "PYTHONPATH",
    "PYTHONSTARTUP",
    "PROJ_LIB",
    "PROJ_DATA",
    "GDAL_DATA",
    "GDAL_DRIVER_PATH",
    "QGIS_PREFIX_PATH",
)


def command_environment() -> dict:
    """This process's environment without QGIS's own Python and library paths, unbuffered."""
    env = {k: v for k, v in os.environ.items() if k not in QGIS_ONLY}
    return dict(env, PYTHONUNBUFFERED="1", PYTHONIOENCODING="utf-8")


def _detached() -> dict:
    """Popen options: its own process group (cancel reaches what it starts), no console window on Windows."""
    if os.name == "nt":
        return {"creationflags": subprocess.CREATE_NEW_PROCESS_GROUP | getattr(subprocess, "CREATE_NO_WINDOW", 0)}
    return {"start_new_session": True}


class CommandError(Exception):
    """The command is missing, broken, or failed: one line for the user."""


class Canceled(Exception):
    """The user canceled; the command was stopped."""


def find_command(configured: str | None) -> str:
    """The csboundary executable: the plugin's setting, else $CSBOUNDARY_COMMAND, else the one on PATH."""
    command = (configured or "").strip() or os.environ.get(COMMAND_ENV, "").strip() or shutil.which("csboundary")
    command = os.path.expanduser(command) if command else command
    if not command:
        raise CommandError(
            "no csboundary command found: install csboundary in a Python environment "
            f"(pip install csboundary) and give its csboundary executable under {SETTING_PLACE}"
        )
    if not os.path.isfile(command) or not os.access(command, os.X_OK):
        raise CommandError(
            f"{command}: not an executable file; give the csboundary executable of the environment "
            f"where csboundary is installed under {SETTING_PLACE}"
        )
    return command


def check_command(command: str, timeout: float = 120.0) -> str:
    """The version the command reports (``csboundary 0.1.0``); a command that does not run as
    csboundary is a :class:`CommandError` naming what it printed."""
    try:
        done = subprocess.run(
            [command, "--version"],
            capture_output=True,
            text=True,
            timeout=timeout,
            env=command_environment(),
            **({"creationflags": getattr(subprocess, "CREATE_NO_WINDOW", 0)} if os.name == "nt" else {}),
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise CommandError(f"{command}: does not run ({exc})") from None
    said = (done.stdout + done.stderr).strip()
    if done.returncode != 0 or not said.startswith("csboundary "):
        raise CommandError(
            f"{command}: the csboundary environment is broken ({last_line(said) or f'exit {done.returncode}'}); "
            "reinstall csboundary there"
        )
    return said.splitlines()[0]


def last_line(text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else ""


def failure(lines: list[str], returncode: int) -> str:
    """One line for a failed run: the command's own ``error:`` line, else (a traceback: the
    environment, not the input) its last line."""
    errors = [line for line in lines if line.startswith("error:")]
    if errors:
        return errors[-1][len("error:") :].strip()
    if any(line.startswith("Traceback") for line in lines):
        return f"the csboundary environment is broken ({last_line(chr(10).join(lines))}); reinstall csboundary there"
    return last_line("\n".join(lines)) or f"csboundary stopped with exit status {returncode}"


@dataclass
class Progress:
    """Where the output of a run goes: a stage's name and percentage, and every other line."""

    stage: Callable[[str], None] = lambda text: None
    percent: Callable[[float], None] = lambda value: None
    line: Callable[[str], None] = lambda text: None
    canceled: Callable[[], bool] = lambda: False
    lines: list[str] = field(default_factory=list)  # every line that is not a bar, for the failure's message
    current: str = ""  # the stage whose bar was last seen

    def take(self, piece: str) -> None:
        """One piece of output (between carriage returns or newlines)."""
        piece = piece.rstrip()
        if not piece:
            return
        bar = _BAR.match(piece)
        if bar:
            stage = bar.group("stage").strip()
            if stage != self.current:
                self.current = stage
                self.stage(stage)
            self.percent(min(100.0, float(bar.group("percent"))))
            piece = bar.group("rest").strip()
            if not piece:
                return
        self.lines.append(piece)
        self.line(piece)


def run(command: str, args: list[str], progress: Progress, poll: float = 0.1, grace: float = 4.0) -> list[str]:
    """Run ``command args``, feeding ``progress`` as the output comes; return the output lines.

    On cancel the command's process group gets SIGTERM (Ctrl-Break on Windows; csboundary then
    removes its temporaries and exits, and a predict run keeps its finished patches for the same
    command to continue) and, after ``grace`` seconds, SIGKILL. Raises :class:`Canceled` or, on a
    non-zero exit, :class:`CommandError`. The command never outlives this call."""
    try:
        process = subprocess.Popen(
            [command, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=command_environment(), **_detached()
        )
    except OSError as exc:
        raise CommandError(f"{command}: does not run ({exc})") from None
    pieces: queue.Queue = queue.Queue()
    reader = threading.Thread(target=_read, args=(process.stdout, pieces), daemon=True)
    reader.start()
    try:
        while True:
            _drain(pieces, progress)
            if process.poll() is not None:
                break
            if progress.canceled():
                stop(process, grace)
                reader.join(timeout=1.0)
                _drain(pieces, progress)
                raise Canceled()
            time.sleep(poll)
    finally:
        if process.poll() is None:  # a callback failed, or the caller's thread was interrupted
            stop(process, grace)
    reader.join(timeout=5.0)
    _drain(pieces, progress)
    if process.returncode != 0:
        raise CommandError(failure(progress.lines, process.returncode))
    return progress.lines


def stop(process: subprocess.Popen, grace: float) -> None:
    """Ask the command and what it started to stop (SIGTERM; Ctrl-Break on Windows), then kill
    whatever is left after ``grace`` seconds."""

    def ask() -> None:
        try:
            if os.name == "nt":
                process.send_signal(signal.CTRL_BREAK_EVENT)
            else:
                os.killpg(process.pid, signal.SIGTERM)
        except (ProcessLookupError, PermissionError, OSError):
            pass

    def kill() -> None:
        try:
            if os.name == "nt":
                process.kill()
            else:
                os.killpg(process.pid, signal.SIGKILL)  # the group too: a worker the command started must not linger
        except (ProcessLookupError, PermissionError, OSError):
            pass

    ask()
    try:
        process.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        pass
    kill()
    process.wait()


def _read(stream, pieces: queue.Queue) -> None:
    """Split the byte stream on carriage returns (a bar redrawn) and newlines, as it comes."""
    rest = b""
    while True:
        chunk = os.read(stream.fileno(), 65536)
        if not chunk:
            break
        parts = re.split(rb"[\r\n]", rest + chunk)
        rest = parts.pop()
        for part in parts:
            pieces.put(part.decode("utf-8", "replace"))
    if rest:
        pieces.put(rest.decode("utf-8", "replace"))
    stream.close()


def _drain(pieces: queue.Queue, progress: Progress) -> None:
    while True:
        try:
            progress.take(pieces.get_nowait())
        except queue.Empty:
            return
