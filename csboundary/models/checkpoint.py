"""Checkpoints: weights plus everything needed to trust and reproduce them.

A checkpoint is a ``torch.save`` dict with ``format``, ``kind`` (fpn | afanet | bundle), the
model config, the training config, step, validation metrics, code version and, while training,
optimizer and RNG states (so a run resumes exactly). Shipped weights are a ``bundle`` holding
both models without optimizer state.
"""

from __future__ import annotations

import pickle
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import torch

from csboundary import __version__
from csboundary.data.atomic import atomic_path
from csboundary.errors import InputError

FORMAT = "csboundary-checkpoint"


def code_version() -> str:
    """Package version plus the git commit when running from a checkout."""
    try:
        root = Path(__file__).resolve().parents[2]
        sha = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=5
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=5,
        ).stdout.strip()
        return f"{__version__}+{sha}{'.dirty' if dirty else ''}" if sha else __version__
    except (OSError, subprocess.SubprocessError):
        return __version__


SHIPPED_WEIGHTS = "csboundary-synthetic.pt"


def shipped_weights() -> Path:
    """Path of the weights shipped inside the package (trained by ``csboundary train``)."""
    from importlib import resources

    return Path(str(resources.files("csboundary") / "weights" / SHIPPED_WEIGHTS))


_DIGESTS: dict[tuple[str, int, int], str] = {}


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file (identifies weights in a run's manifest and their ONNX exports);
    remembered per path, size and modification time, so one run hashes its weights once."""
    import hashlib

    stat = Path(path).stat()
    key = (str(Path(path).resolve()), stat.st_size, stat.st_mtime_ns)
    if key not in _DIGESTS:
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        _DIGESTS[key] = digest.hexdigest()
    return _DIGESTS[key]


def save_checkpoint(path: str | Path, kind: str, **content: Any) -> Path:
    payload = {"format": FORMAT, "kind": kind, "code_version": code_version(), **content}
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return Path(path)


def load_fpn(source: str | Path | dict, device: torch.device | str = "cpu", path: str | Path | None = None):
    """csBoundary's FPN, in eval mode on ``device``, from an ``fpn`` checkpoint or a bundle (a
    path, or a payload already loaded from ``path``)."""
    from csboundary.models.fpn import fpn_for_weights

    payload = source if isinstance(source, dict) else load_checkpoint(source, ("fpn", "bundle"), map_location=device)
    where = path if path is not None else ("<weights>" if isinstance(source, dict) else source)
    fpn = restore_model(where, "fpn", payload, fpn_for_weights)
    return fpn.to(device).eval().to(memory_format=torch.channels_last)


def load_afanet(source: str | Path | dict, device: torch.device | str = "cpu", path: str | Path | None = None):
    """AfANet, in eval mode on ``device``, from an ``afanet`` checkpoint or a bundle (a path, or a
    payload already loaded from ``path``)."""
    from csboundary.models.afanet import AfANet, AfANetConfig

    payload = source if isinstance(source, dict) else load_checkpoint(source, ("afanet", "bundle"), map_location=device)
    where = path if path is not None else ("<weights>" if isinstance(source, dict) else source)
    return restore_model(where, "afanet", payload, lambda c: AfANet(AfANetConfig.from_dict(c))).to(device).eval()


def restore_model(path: str | Path, name: str, payload: dict, build):
    """``build(payload[name + "_config"])`` with ``payload[name]`` loaded into it; a missing field, a
    config the code cannot build or tensors that do not fit it is one InputError naming the file."""
    for key in (name, f"{name}_config"):
        if key not in payload:
            raise InputError(path, f"damaged weights file: no {key!r} entry")
    config, state = payload[f"{name}_config"], payload[name]
    if (
        not isinstance(config, dict)
        or not isinstance(state, dict)
        or not all(isinstance(v, torch.Tensor) for v in state.values())
    ):
        raise InputError(path, f"damaged weights file: {name!r} is not a model config and a dict of tensors")
    try:
        model = build(config)
    except (TypeError, ValueError, KeyError) as exc:
        raise InputError(path, f"damaged weights file: the {name} config cannot be built ({exc})") from exc
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        problem = " ".join(str(exc).split())
        raise InputError(
            path, f"damaged weights file: the {name} tensors do not fit its config ({problem[:160]})"
        ) from exc
    return model


# Plain data that older checkpoints pickled as numpy scalars (e.g. a validation metric): numpy's
# scalar reconstructor and dtypes only build numbers, never run code.
try:
    from numpy._core.multiarray import scalar as _numpy_scalar  # numpy >= 2
except ImportError:  # pragma: no cover - numpy 1.x
    from numpy.core.multiarray import scalar as _numpy_scalar
_SAFE_NUMPY = [_numpy_scalar, np.dtype, *{type(np.dtype(t)) for t in ("float64", "float32", "int64", "int32", "bool")}]


def load_checkpoint(path: str | Path, kinds: tuple[str, ...], map_location="cpu") -> dict[str, Any]:
    """Load a checkpoint and check that it holds one of ``kinds``; errors name the file.

    Loading never runs code from the file: ``weights_only=True`` unpickles tensors and plain
    data only (plus numpy scalars), so a weights file from a stranger cannot execute anything.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "weights file not found")
    if path.is_dir():
        raise InputError(path, "is a folder, not a weights file")
    try:
        with torch.serialization.safe_globals(_SAFE_NUMPY):
            payload = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        if "GLOBAL" in str(exc) or "global" in str(exc):  # the safe unpickler met a class or function
            raise InputError(
                path,
                "refused: the file holds Python objects, not only tensors and plain data (loading it could run code)",
            ) from exc
        raise InputError(path, f"not a readable weights file ({type(exc).__name__})") from exc
    except Exception as exc:  # torch raises many types for foreign or damaged files
        raise InputError(path, f"not a readable weights file ({type(exc).__name__})") from exc
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise InputError(path, "not a csboundary weights file")
    if payload.get("kind") not in kinds:
        raise InputError(path, f"holds a {payload.get('kind')!r} model; expected {' or '.join(kinds)}")
    return payload
