"""Which ONNX Runtime graph optimisation level runs each network fastest on this machine.

ONNX Runtime's top level ("all") rewrites convolutions into its blocked NCHWc layout. Whether that
pays depends on the CPU's vector width and on the network's channel counts: on an AVX-512 Xeon
(this project's test machine) it made the shipped FPN 1.4x slower (its EfficientNet's 1x1 expansions, 120 -> 720 channels
at 36 x 36, took 19 ms instead of 2) and AfANet 1.4x faster. So the first ``onnx`` run of a
weights file on a machine times both levels for each network on inputs of the pipeline's shape
(a few seconds, beside the export's own) and records the choice in a JSON file beside the
exports, keyed by the CPU, the onnxruntime version and the thread count; later runs read it.
Delete the file to time again. Both levels compute the same function (the test suite checks each
against PyTorch within 1e-5), so the choice moves speed, not results beyond float rounding.
"""

from __future__ import annotations

import json
import math
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np

from csboundary.models.device import cpuinfo_value
from csboundary.models.onnx_session import LEVELS, open_session

TIMED_RUNS = 3  # per level, alternated, after one warm-up run each; the fastest run counts
TUNING_VERTICES = 100  # AfANet's vertex count while timing: a busy window of the test cities


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else what ``platform`` knows."""
    return cpuinfo_value("model name") or platform.processor() or platform.machine() or "unknown CPU"


def machine_key(threads: int) -> str:
    """What a timing holds for: the CPU, the onnxruntime version and the thread count."""
    import onnxruntime

    return f"{cpu_name()} | onnxruntime {onnxruntime.__version__} | {threads} threads"


def example_inputs(session) -> dict[str, np.ndarray]:
    """Random inputs of the shapes ``session`` declares: a batch of one window for the FPN,
    ``TUNING_VERTICES`` vertices for AfANet's views."""
    rng = np.random.default_rng(0)
    sizes = {"batch": 1, "m": TUNING_VERTICES}
    return {
        i.name: rng.random([d if isinstance(d, int) else sizes[d] for d in i.shape], dtype=np.float32)
        for i in session.get_inputs()
    }


def fastest_level(seconds: dict[str, float]) -> str:
    """The level with the least time; on a tie the one listed first in ``LEVELS`` (the default)."""
    return min(LEVELS, key=lambda level: (seconds.get(level, math.inf), LEVELS.index(level)))


def time_levels(
    model: bytes, name: str, threads: int, runs: int = TIMED_RUNS, clock: Callable[[], float] = time.perf_counter
) -> dict[str, float]:
    """Fastest of ``runs`` timed runs of ``model`` at each level, the levels alternated so that
    a change in the machine's load falls on both."""
    sessions = {level: open_session(model, threads, level, name) for level in LEVELS}
    inputs = example_inputs(sessions[LEVELS[0]])
    for session in sessions.values():
        session.run(None, inputs)  # first run: memory planning, not steady state
    best = {level: math.inf for level in LEVELS}
    for _ in range(runs):
        for level, session in sessions.items():
            start = clock()
            session.run(None, inputs)
            best[level] = min(best[level], clock() - start)
    return best


def _recorded(path: Path, key: str) -> dict:
    """The entry recorded for ``key`` in ``path`` with only its valid levels; {} if absent,
    unreadable or not valid."""
    try:
        entry = json.loads(path.read_text()).get(key, {})
        levels, seconds = entry.get("levels", {}), entry.get("seconds", {})
    except (OSError, ValueError, AttributeError):
        return {}
    if not isinstance(levels, dict):
        return {}
    seconds = seconds if isinstance(seconds, dict) else {}
    valid = {name: level for name, level in levels.items() if level in LEVELS}
    return {"levels": valid, "seconds": {name: seconds.get(name) for name in valid}}


def recorded_seconds(path: Path, threads: int, levels: dict[str, str]) -> dict[str, float]:
    """Each network's fastest timed run at its level ``levels[name]`` on this machine, as
    recorded in ``path``; networks without a valid record are left out."""
    seconds = _recorded(path, machine_key(threads)).get("seconds", {})
    out = {}
    for name, level in levels.items():
        value = (seconds.get(name) or {}).get(level) if isinstance(seconds.get(name), dict) else None
        if isinstance(value, (int, float)) and math.isfinite(value) and value > 0:
            out[name] = float(value)
    return out


def tuned_levels(path: Path, models: dict[str, bytes], threads: int) -> dict[str, str]:
    """Each network's level for this machine (``models``: name -> ONNX model): read from
    ``path``, else timed and added to it (only the networks not recorded yet are timed)."""
    from csboundary.data.atomic import atomic_path

    key = machine_key(threads)
    entry = _recorded(path, key)
    levels = dict(entry.get("levels", {}))
    missing = [name for name in models if name not in levels]
    if not missing:
        return {name: levels[name] for name in models}
    seconds = dict(entry.get("seconds", {}))
    print(
        f"csboundary: timing ONNX Runtime's optimisation levels for {', '.join(missing)} on this machine (once)",
        file=sys.stderr,
        flush=True,
    )
    for name in missing:
        times = time_levels(models[name], name, threads)
        levels[name] = fastest_level(times)
        seconds[name] = {k: round(v, 4) for k, v in times.items()}
    try:
        record = json.loads(path.read_text())
        record = record if isinstance(record, dict) else {}
    except (OSError, ValueError):
        record = {}  # none yet, or damaged: timed again and replaced
    record[key] = {
        "levels": levels,
        "seconds": seconds,
        "measured": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    try:
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(record, indent=1) + "\n")
    except OSError:
        pass  # a worker that cannot write there (another machine's cache folder) keeps its timing unrecorded
    return {name: levels[name] for name in models}
