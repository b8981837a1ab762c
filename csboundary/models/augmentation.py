"""Training augmentation: the imagery a user has is never our generator's.

Geometry (any-angle rotation, scale, flips) is applied to the image, its label maps and its
validity mask together; appearance (brightness, contrast, gamma, hue, saturation, colour balance,
blur, noise, JPEG artefacts, NIR replaced by green as RGB-only inputs are read) to the image only.
Off by default, for runs with a road-surface head: foreign clutter painted over the non-road area
(:func:`paint_surface_negatives`).
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
    # road-surface samples: probability of painting foreign clutter over the non-road area (paint_surface_negatives); 0 = off
    surface_negatives: float = 0.0
    surface_negatives_margin_px: tuple[int, int] = (6, 24)  # untouched band around the roadway and every boundary
    surface_negatives_cover: tuple[float, float] = (0.4, 1.0)  # share of the paintable area painted


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
    out = [
        cv2.warpAffine(
            np.ascontiguousarray(p), matrix, (crop, crop), flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0
        )
        for p in planes
    ]
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
    m = np.array(
        [
            [c + (1 - c) * k, k * (1 - c) - sq * s, k * (1 - c) + sq * s],
            [k * (1 - c) + sq * s, c + k * (1 - c), k * (1 - c) - sq * s],
            [k * (1 - c) - sq * s, k * (1 - c) + sq * s, c + k * (1 - c)],
        ],
        np.float32,
    )
    return np.einsum("ij,jhw->ihw", m, rgb)


def _jpeg(x: np.ndarray, quality: int) -> np.ndarray:
    """JPEG-compress the RGB bands (blocking, ringing, chroma subsampling) and decode them."""
    rgb = (np.moveaxis(x[:3], 0, -1) * 255 + 0.5).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
    if ok:
        x = x.copy()
        x[:3] = np.moveaxis(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1], -1, 0).astype(np.float32) / 255
    return x


def paint_surface_negatives(
    rng: np.random.Generator, image: np.ndarray, target: np.ndarray, valid: np.ndarray, config: AugmentConfig
) -> np.ndarray:
    """With probability ``config.surface_negatives``, ``image`` (bands, s, s) with part of its
    non-road area repainted with :func:`dead_leaves` clutter; else ``image`` itself (no random
    draw when the option is 0, so runs without it are unchanged). ``target`` is the FPN target
    with the road surface as third channel (1 roadway, 0 not, -1 unknown; a 2-channel target is
    never painted). Painted: valid pixels whose surface is 0, farther than a random margin
    (``surface_negatives_margin_px``) from the roadway and from every boundary pixel, inside
    random blobs covering ``surface_negatives_cover`` of them; the targets stay true (not road,
    no boundary), the curb and what lies beside it stay as rendered.

    Why (issue 66): on real suburbs the surface head gives lawns, roofs, driveways and shadows
    about 0.4 (Ottawa crops; roads 0.73), on every rendered non-road pixel about 0.01 whatever its
    colour (greyscale, Ottawa's colour statistics or per-region recolouring keep it under 0.05):
    it learnt the renderer's lawns and roofs, not the roadway, and answers near its prior on
    anything else. Clutter of every scale, colour and texture (the shipped head: about 0.2 on it),
    labelled not-road, is what it has never been shown."""
    if config.surface_negatives <= 0 or not config.enabled or target.shape[0] < 3:
        return image
    if rng.random() >= config.surface_negatives:
        return image
    road, size = target[2], image.shape[-1]
    protect = ((road >= 0.5) | (target[1] >= 0.5)).astype(np.uint8)
    paintable = (road == 0) & valid
    if protect.any():
        margin = float(rng.uniform(*config.surface_negatives_margin_px))
        paintable &= cv2.distanceTransform(1 - protect, cv2.DIST_L2, 3) > margin
    blobs = _smooth_noise(rng, image.shape[-2:], float(rng.uniform(24, 96)))
    cover = float(rng.uniform(*config.surface_negatives_cover))
    paint = paintable & (blobs >= np.quantile(blobs, 1 - cover)) if cover < 1 else paintable
    if not paint.any():
        return image
    clutter = dead_leaves(rng, size)
    out = image.copy()
    out[:3, paint] = clutter[:, paint]
    if len(out) > 3:
        out[3, paint] = clutter[1, paint]  # NIR unknown: as RGB-only imagery is read
    return out


def dead_leaves(
    rng: np.random.Generator,
    size: int,
    shapes: tuple[int, int] = (300, 900),
    radius_px: tuple[float, float] = (3.0, 80.0),
    grey_share: float = 0.5,
) -> np.ndarray:
    """(3, size, size) float32 in [0, 1]: a dead-leaves picture (discs, rotated rectangles and
    polygons over each other, the large ones beneath; radii log-uniform, so that the plane is
    covered several times over and every scale from 0.5 to 12 m shows), half of the shapes grey
    from asphalt to concrete, the rest of muted to full colour; then a texture of random
    strength, soft shadows on half of them, and a slight blur."""
    canvas = np.empty((size, size, 3), np.float32)
    canvas[:] = rng.uniform(0.1, 0.6)
    lo, hi = radius_px
    radii = np.sort(lo * (hi / lo) ** rng.random(int(rng.integers(*shapes))))[::-1]
    for r in radii:
        grey = rng.uniform(0.12, 0.7)
        if rng.random() < grey_share:
            colour = grey * rng.uniform(0.96, 1.04, 3)
        else:
            colour = grey + (rng.uniform(0.05, 0.75, 3) - grey) * rng.uniform(0.2, 1.0)
        centre = rng.uniform(-r, size + r, 2)
        kind = rng.integers(3)
        if kind == 0:
            cv2.circle(canvas, (int(centre[0]), int(centre[1])), max(int(r), 1), colour.tolist(), -1)
        else:
            if kind == 1:
                points = cv2.boxPoints(
                    ((centre[0], centre[1]), (2 * r, 2 * r * rng.uniform(0.15, 1.0)), rng.uniform(0, 180))
                )
            else:
                points = cv2.convexHull((centre + rng.uniform(-r, r, (int(rng.integers(3, 8)), 2))).astype(np.float32))
            cv2.fillConvexPoly(canvas, np.round(points).astype(np.int32).reshape(-1, 2), colour.tolist())
    out = np.moveaxis(canvas, -1, 0)
    shape = (size, size)
    texture = 0.6 * _smooth_noise(rng, shape, float(rng.uniform(1, 3))) + 0.4 * _smooth_noise(
        rng, shape, float(rng.uniform(4, 16))
    )
    out = out * (1 + float(rng.uniform(0.0, 0.2)) * texture)
    if rng.random() < 0.5:
        shade = cv2.GaussianBlur(
            (_smooth_noise(rng, shape, float(rng.uniform(20, 60))) > 0.6).astype(np.float32), (0, 0), 2.0
        )
        out = out * (1 - float(rng.uniform(0.3, 0.6)) * shade)
    sigma = float(rng.uniform(0.0, 1.0))
    if sigma > 0.3:
        out = np.stack([cv2.GaussianBlur(b, (0, 0), sigma) for b in out])
    return np.clip(out, 0, 1).astype(np.float32)


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], scale: float) -> np.ndarray:
    """(h, w) float32 noise of about unit variance with correlation length ~``scale`` px."""
    h, w = shape
    coarse = rng.standard_normal((max(2, round(h / scale)) + 1, max(2, round(w / scale)) + 1)).astype(np.float32)
    return cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
