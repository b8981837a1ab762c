"""The run store's float16 maps, converted by PyTorch's vectorized kernels on the calling thread.

Stored maps are float16 (half the memory and disk of float32). NumPy converts float16 slowly:
on this machine 7.4 ms to store a (3, 1100, 1100) patch and 4.8 ms to add one into a float32
sum. PyTorch's kernels give the same bits (same IEEE round-to-nearest-even;
tests/pipeline/prediction/test_float16.py) in a fraction of that, but an operation on more than
``SERIAL_ELEMENTS`` values wakes PyTorch's thread pool, and beside an FPN that keeps every core
busy those threads wait for a core: with a busy thread beside it, one call took 16 ms to add and
8 ms to store, cut into pieces that PyTorch runs on the calling thread 1.9 and 1.5 ms
(benchmarks/float16_speed.py, runs/float16-speed.txt).
"""

from __future__ import annotations

import numpy as np
import torch

SERIAL_ELEMENTS = 32768  # PyTorch's grain size: smaller elementwise operations stay on the calling thread


def to_float16(maps: np.ndarray, step: int = SERIAL_ELEMENTS) -> np.ndarray:
    """``maps.astype(np.float16)``, bit for bit, in a fraction of the time, on this thread
    (``step``: values converted per call)."""
    maps = np.ascontiguousarray(maps, np.float32)
    source = torch.from_numpy(maps).view(-1)
    out = torch.empty(source.shape, dtype=torch.float16)
    for start in range(0, source.numel(), step):
        out[start : start + step].copy_(source[start : start + step])
    return out.numpy().reshape(maps.shape)


def add_float32(total: np.ndarray, part: np.ndarray, step: int = SERIAL_ELEMENTS) -> None:
    """``total += part`` in float32 (``part`` float16 or float32, a writable array or view of the
    same shape), bit for bit as NumPy adds them, on this thread (``step``: about the values
    added per call, in whole rows of the last axis)."""
    if total.shape != part.shape:
        raise ValueError(f"cannot add {part.shape} into {total.shape}")
    into, values = torch.from_numpy(total), torch.from_numpy(part)
    if into.ndim < 2:  # a scalar or one row: rows of one value each
        into, values = into.reshape(-1, 1), values.reshape(-1, 1)
    per_call = max(1, step // max(into.shape[-1], 1))
    for lead in np.ndindex(*into.shape[:-2]):  # each plane (one channel) in turn; views, never copies
        plane, source = into[lead], values[lead]
        for row in range(0, plane.shape[0], per_call):
            plane[row : row + per_call].add_(source[row : row + per_call])
