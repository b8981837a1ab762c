"""Training augmentation: the imagery a user has is never our generator's.

Geometry (any-angle rotation, scale, flips) is applied to the image, its label maps and its
validity mask together; appearance (brightness, contrast, gamma, hue, saturation, colour balance,
blur, noise, JPEG artefacts, NIR replaced by green as RGB-only inputs are read) to the image only.
Every function takes a ``numpy`` random generator, so a seeded run draws the same samples.
Images are (bands, h, w) float32 in [0, 1]; bands are R, G, B, NIR.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from csboundary.config import Config


@dataclass(frozen=True)
class AugmentConfig(Config):
    """Ranges of every random change; ``enabled = False`` keeps only flips and 90-degree turns."""
    config_name = "augment"

    enabled: bool = True
    rotate: bool = True  # any angle
    scale: tuple[float, float] = (0.7, 1.4)  # >1 zooms in (objects larger)
    brightness: float = 0.15  # added, +-
    contrast: tuple[float, float] = (0.6, 1.4)
    gamma: tuple[float, float] = (0.7, 1.5)
    hue: float = 0.06  # fraction of the hue circle, +-
    saturation: tuple[float, float] = (0.3, 1.5)
    channel_gain: float = 0.12  # per-band gain (colour balance), +-
    blur_p: float = 0.3
    blur_sigma: tuple[float, float] = (0.3, 1.5)
    noise_p: float = 0.5
    noise_sigma: tuple[float, float] = (0.005, 0.04)
    jpeg_p: float = 0.3
    jpeg_quality: tuple[int, int] = (30, 90)
    nir_as_green_p: float = 0.5  # RGB-only imagery is read with NIR := green; train on it as often


def source_side(crop: int, angle: float, scale: float) -> int:
    """Side of the square source window that covers a ``crop`` output rotated by ``angle``
    (radians) and zoomed by ``scale``."""
    return int(math.ceil(crop / scale * (abs(math.cos(angle)) + abs(math.sin(angle))))) + 2


def draw_geometry(rng: np.random.Generator, config: AugmentConfig) -> tuple[float, float]:
    """(angle in radians, scale) of one sample."""
    if not config.enabled:
        return 0.0, 1.0
    angle = float(rng.uniform(0, 2 * math.pi)) if config.rotate else 0.0
    lo, hi = config.scale
    scale = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    return angle, scale


def warp(array: np.ndarray, angle: float, scale: float, crop: int, nearest: bool = False) -> np.ndarray:
    """The centred ``crop`` x ``crop`` view of ``array`` (..., S, S) rotated by ``angle`` and
    zoomed by ``scale`` about its centre; outside the source is 0."""
    side = array.shape[-1]
    matrix = cv2.getRotationMatrix2D(((side - 1) / 2, (side - 1) / 2), math.degrees(angle), scale)
    matrix[:, 2] += (crop - side) / 2
    flags = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    planes = array.reshape(-1, side, side)
    out = [cv2.warpAffine(np.ascontiguousarray(p), matrix, (crop, crop), flags=flags, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=0) for p in planes]
    return np.stack(out).reshape(*array.shape[:-2], crop, crop)


def flip_rotate90(rng: np.random.Generator, *arrays: np.ndarray) -> list[np.ndarray]:
    """The same random flip / 90-degree rotation applied to every (..., h, w) array."""
    k = int(rng.integers(4))
    flip = bool(rng.integers(2))
    out = []
    for a in arrays:
        a = np.rot90(a, k, axes=(-2, -1))
        if flip:
            a = a[..., ::-1]
        out.append(np.ascontiguousarray(a))
    return out


def photometric(rng: np.random.Generator, image: np.ndarray, config: AugmentConfig) -> np.ndarray:
    """A randomly re-lit, re-coloured, degraded copy of ``image`` (bands, h, w) in [0, 1]."""
    if not config.enabled:
        return image
    x = image.astype(np.float32, copy=True)
    rgb = x[:3]
    gray = rgb.mean(axis=0, keepdims=True)
    rgb[:] = gray + (rgb - gray) * rng.uniform(*config.saturation)
    if config.hue:
        rgb[:] = _rotate_hue(rgb, float(rng.uniform(-config.hue, config.hue)))
    x *= (1 + rng.uniform(-config.channel_gain, config.channel_gain, size=(len(x), 1, 1))).astype(np.float32)
    mean = x.mean(axis=(1, 2), keepdims=True)
    x = (x - mean) * rng.uniform(*config.contrast) + mean + rng.uniform(-config.brightness, config.brightness)
    x = np.clip(x, 0, 1) ** rng.uniform(*config.gamma)
    if rng.random() < config.blur_p:
        sigma = float(rng.uniform(*config.blur_sigma))
        x = np.stack([cv2.GaussianBlur(b, (0, 0), sigma) for b in x])
    if rng.random() < config.noise_p:
        x = x + rng.normal(0, rng.uniform(*config.noise_sigma), x.shape).astype(np.float32)
    x = np.clip(x, 0, 1).astype(np.float32)
    if rng.random() < config.jpeg_p:
        x = _jpeg(x, int(rng.integers(config.jpeg_quality[0], config.jpeg_quality[1] + 1)))
    if len(x) > 3 and rng.random() < config.nir_as_green_p:
        x[3] = x[1]
    return x


def _rotate_hue(rgb: np.ndarray, turns: float) -> np.ndarray:
    """Rotate hue by ``turns`` of the circle (rotation about the grey axis: keeps luminance mean)."""
    theta = 2 * math.pi * turns
    c, s = math.cos(theta), math.sin(theta)
    k = 1 / 3
    sq = math.sqrt(k)
    m = np.array([
        [c + (1 - c) * k, k * (1 - c) - sq * s, k * (1 - c) + sq * s],
        [k * (1 - c) + sq * s, c + k * (1 - c), k * (1 - c) - sq * s],
        [k * (1 - c) - sq * s, k * (1 - c) + sq * s, c + k * (1 - c)],
    ], np.float32)
    return np.einsum("ij,jhw->ihw", m, rgb)


def _jpeg(x: np.ndarray, quality: int) -> np.ndarray:
    """JPEG-compress the RGB bands (blocking, ringing, chroma subsampling) and decode them."""
    rgb = (np.moveaxis(x[:3], 0, -1) * 255 + 0.5).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
    if ok:
        x = x.copy()
        x[:3] = np.moveaxis(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1], -1, 0).astype(np.float32) / 255
    return x
