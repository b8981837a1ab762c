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


def cpuinfo_value(field: str, cpuinfo: str = "/proc/cpuinfo") -> str | None:
    """The first ``field`` line's value in ``/proc/cpuinfo`` (e.g. ``model name``, ``flags``);
    None where the file or the field is missing (not Linux)."""
    try:
        with open(cpuinfo) as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == field:
                    return value.strip()
    except OSError:
        pass
    return None


def bfloat16_hardware(device: torch.device, cpuinfo: str = "/proc/cpuinfo") -> bool:
    """Whether ``device`` computes bfloat16 natively: a GPU PyTorch says supports it, or a CPU
    with AMX tiles or AVX512-BF16 (elsewhere bfloat16 is emulated and slower than float32).
    Without ``/proc/cpuinfo`` (not Linux) the answer is no: the user is warned and may go on."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    flags = (cpuinfo_value("flags", cpuinfo) or "").split()
    return "amx_bf16" in flags or "avx512_bf16" in flags
