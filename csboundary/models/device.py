"""``--device auto|cpu|cuda``: one place that turns the user's choice into a torch device."""

from __future__ import annotations

import torch

from csboundary.errors import InputError


def resolve_device(name: str = "auto") -> torch.device:
    """``auto`` picks CUDA when present; asking for ``cuda`` without a GPU is an error, not a fallback."""
    name = name.lower()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise InputError("--device", "cuda was asked for, but PyTorch sees no CUDA device (use --device cpu or auto)")
    if name not in ("cpu", "cuda") and not (name.startswith("cuda:") and name[5:].isdigit()):
        raise InputError("--device", f"must be auto, cpu, cuda or cuda:N, got {name!r}")
    if name.startswith("cuda:") and int(name[5:]) >= torch.cuda.device_count():
        raise InputError("--device", f"{name} asked for, but PyTorch sees {torch.cuda.device_count()} CUDA device(s)")
    return torch.device(name)
