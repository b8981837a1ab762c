"""FPN probability maps for whole mosaics, averaged where expanded patches overlap (paper IV-E).

"We stitch predicted keypoint maps by averaging the intersection areas": every patch's 1100 px
prediction is added into the mosaic-wide sum and count, so in an overlap every pixel is the
mean of the patches covering it and neighbours agree exactly.
"""

from __future__ import annotations

import numpy as np
import torch
from tqdm import tqdm

from csboundary.data.grid import PatchGrid
from csboundary.data.nodata import fill_nodata
from csboundary.data.raster import Mosaic
from csboundary.errors import InputError
from csboundary.models.fpn import FPN


def image_tensor(data: np.ndarray, device: torch.device) -> torch.Tensor:
    """(4, h, w) uint8 bands -> float tensor in [0, 1] on ``device``."""
    return torch.from_numpy(unit_bands(data)).to(device=device)


def unit_bands(data: np.ndarray) -> np.ndarray:
    """8-bit bands -> float32 in [0, 1]: the only input scale the networks were trained on.

    Other data types have no agreed range (12-bit, 16-bit, reflectance), so guessing one would
    give silently wrong maps; they are refused (rescale to 8 bits first, e.g. gdal_translate
    -ot Byte -scale).
    """
    if data.dtype != np.uint8:
        raise InputError("<imagery>", f"the networks take 8-bit imagery; got {data.dtype} (rescale to 0-255 first)")
    return np.divide(data, np.float32(255.0), dtype=np.float32)  # one pass; the same values as casting, then dividing


def bands_and_maps(data: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """(4, h, w) uint8 bands and the (2+, h, w) maps -> AfANet's (6, h, w) float32 input (keypoint
    and boundary maps; a surface channel is not AfANet's), written in place (no concatenation
    copy); the bands scaled exactly as :func:`unit_bands` does."""
    maps = maps[:2]
    if data.dtype != np.uint8:
        unit_bands(data)  # the same refusal
    out = np.empty((data.shape[0] + maps.shape[0], *data.shape[1:]), np.float32)
    np.divide(data, np.float32(255.0), out=out[: data.shape[0]], dtype=np.float32)
    out[data.shape[0] :] = maps
    return out


PRECISIONS = ("float32", "bfloat16", "int8")  # int8: ONNX Runtime only (models/onnx_quantization.py)


@torch.no_grad()
def predict_probabilities(
    model: FPN, image: np.ndarray, device: torch.device, precision: str = "float32"
) -> np.ndarray:
    """(4, h, w) uint8 -> (C, h, w) float32 probabilities (keypoint, segmentation, and the road
    surface when the FPN has that head); a batch (B, 4, h, w) -> (B, C, h, w).

    ``precision="bfloat16"`` runs the convolutions under bfloat16 autocast: 2.1x faster on CPUs
    with AMX tiles (measured, docs/cpu-inference.md), at the cost of probabilities off by up to
    ~0.1 at single pixels; the weights and the returned maps stay float32."""
    model.eval()
    batch = image_tensor(image, device)
    # channels-last: 1.3-2.3x faster convolutions on CPU (benchmarks/fpn_speed.py), same values
    with torch.autocast(device.type, dtype=torch.bfloat16, enabled=precision == "bfloat16"):
        logits = model((batch if batch.ndim == 4 else batch[None]).contiguous(memory_format=torch.channels_last))
    probs = torch.sigmoid(logits.float()).cpu().numpy()
    return probs if batch.ndim == 4 else probs[0]


def predict_mosaic_maps(
    model: FPN, mosaic: Mosaic, grid: PatchGrid, device: torch.device, progress: bool = True
) -> np.ndarray:
    """(C, H, W) float32 probability maps of the whole mosaic, overlaps averaged (C = 2, or 3
    with a surface head).

    Holds the whole mosaic in memory: fine for training cities; city-scale inference streams.
    """
    total = np.zeros((3 if model.config.surface else 2, mosaic.height, mosaic.width), np.float32)
    count = np.zeros((mosaic.height, mosaic.width), np.float32)
    for patch in tqdm(list(grid), desc="FPN maps", unit="patch", disable=not progress):
        read = mosaic.read(patch.expanded)
        probs = predict_probabilities(model, fill_nodata(read.data, read.valid), device)  # as the city pipeline reads
        part = patch.expanded.intersection(mosaic.window)
        rows, cols = part.slices()
        lrows, lcols = part.relative_to(patch.expanded).slices()
        total[:, rows, cols] += probs[:, lrows, lcols]
        count[rows, cols] += 1
    return total / np.maximum(count, 1)[None]
