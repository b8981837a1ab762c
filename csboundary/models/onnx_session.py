"""What every ONNX Runtime module shares: the window the FPN is exported for, the folder the
exports are cached in, the graph optimisation levels, and the session opener. The engine (:mod:`onnx_engine`), the per-machine
timing of levels (:mod:`onnx_tuning`) and int8 quantization (:mod:`onnx_quantization`) all use
it, and it uses none of them."""

from __future__ import annotations

import os
from pathlib import Path

from csboundary.errors import InputError

WINDOW = 1100  # the city grid's expanded patch side: the FPN input the export is made for

CACHE_ENV = "CSBOUNDARY_CACHE"  # the folder of the cached exports, in place of the user cache


def cache_folder() -> Path:
    """Where the exports are cached (one folder per user, shared by every weights file, keyed by
    the networks: onnx_engine.network_key): ``$CSBOUNDARY_CACHE`` when set, else
    ``$XDG_CACHE_HOME/csboundary/onnx``, else ``~/.cache/csboundary/onnx``. Not checked or made
    here (onnx_engine.cache_dir does that)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "csboundary" / "onnx"


def onnxruntime_available() -> bool:
    try:
        import onnxruntime  # noqa: F401
    except ImportError:
        return False
    return True


# ONNX Runtime's graph optimisation levels a session may use. "all" adds the NCHWc layout
# transform on top of "extended"; which is faster depends on the CPU and the network (measured on
# an AVX-512 Xeon: the shipped FPN 0.29 s with "extended" and 0.41 s with "all", AfANet 39 ms and
# 28 ms), so onnx_tuning times both once per machine.
LEVELS = ("all", "extended")
DEFAULT_LEVEL = "all"  # ONNX Runtime's own default


def open_session(model: bytes, threads: int, level: str, name: str):
    """An ONNX Runtime CPU session for ``model`` on ``threads`` threads at optimisation ``level``."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.log_severity_level = 3
    options.graph_optimization_level = {
        "all": ort.GraphOptimizationLevel.ORT_ENABLE_ALL,
        "extended": ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED,
    }[level]
    # idle pool threads sleep instead of spinning: the city pipeline runs vertex
    # extraction and AfANet beside the FPN, and spinning threads would take their cores
    # (measured: 0.57 -> 0.52 s/patch end to end; the FPN alone is as fast either way)
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    try:
        return ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # a damaged cache file: one line, not a traceback
        raise InputError(
            f"<onnx {name}>",
            f"ONNX Runtime cannot load the exported network ({str(exc).splitlines()[0]}); "
            f"delete the cached exports in {cache_folder()} (made again on next use)",
        ) from exc
