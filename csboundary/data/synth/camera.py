"""What the camera and the air do to a painted tile, the same for every tile of a city.

:mod:`.render` paints what lies on the ground; this module changes how it was photographed: a
:class:`CameraLook` (drawn once per city by :func:`~csboundary.data.synth.city.draw_look`) sets
the sensor's pixel size (:func:`resample` from it to the city's), colour saturation, gamma,
per-band gains, haze, blur and JPEG compression (:func:`apply_look`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class CameraLook:
    """How the sensor and the air change a city's pixels, drawn once per city.

    ``source_gsd`` is the sensor's pixel size: the tile is rendered at it and resampled to the
    city's pixel size (a coarse sensor upsampled looks soft, a fine one downsampled looks crisp).
    """

    source_gsd: float | None = None
    haze: float = 0.0
    saturation: float = 1.0
    gamma: float = 1.0
    gains: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    blur: float = 0.0  # Gaussian blur sigma (px) of the finished tile
    jpeg: int = 0  # JPEG round-trip quality (0: none), the compression of real orthophotos

    @property
    def is_identity(self) -> bool:
        return (
            self.haze == 0
            and self.saturation == 1
            and self.gamma == 1
            and self.gains == (1.0, 1.0, 1.0, 1.0)
            and self.blur == 0
            and self.jpeg == 0
        )


HAZE_VEIL = np.array([196, 202, 212, 180], np.float32)  # a bright, slightly blue veil (NIR less)


def apply_look(image: np.ndarray, look: CameraLook) -> np.ndarray:
    """(4, H, W) uint8 -> same, with saturation, gamma, per-band gains and haze applied."""
    if look.is_identity:
        return image
    x = image.astype(np.float32)
    if look.saturation != 1:
        grey = x[:3].mean(axis=0, keepdims=True)
        x[:3] = grey + (x[:3] - grey) * look.saturation
    if look.gamma != 1:
        x = 255.0 * (np.clip(x, 0, 255) / 255.0) ** look.gamma
    x *= np.asarray(look.gains, np.float32)[:, None, None]
    if look.haze:
        x = x * (1 - look.haze) + HAZE_VEIL[:, None, None] * look.haze
    out = np.clip(x, 0, 255).astype(np.uint8)
    if look.blur > 0:
        out = np.stack([cv2.GaussianBlur(band, (0, 0), look.blur) for band in out])
    if look.jpeg > 0:
        out = jpeg_round_trip(out, look.jpeg)
    return out


def jpeg_round_trip(image: np.ndarray, quality: int) -> np.ndarray:
    """(4, H, W) uint8 -> same after JPEG compression (RGB as one colour image, NIR as grey)."""
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    bgr = np.ascontiguousarray(image[2::-1].transpose(1, 2, 0))  # OpenCV's colour order
    ok, buf = cv2.imencode(".jpg", bgr, params)
    ok2, buf2 = cv2.imencode(".jpg", np.ascontiguousarray(image[3]), params)
    if not (ok and ok2):
        raise RuntimeError("JPEG encoding failed")
    out = np.empty_like(image)
    out[:3] = cv2.imdecode(buf, cv2.IMREAD_COLOR).transpose(2, 0, 1)[::-1]
    out[3] = cv2.imdecode(buf2, cv2.IMREAD_GRAYSCALE)
    return out


def resample(image: np.ndarray, size: int) -> np.ndarray:
    """(4, h, w) uint8 -> (4, size, size): area averaging when shrinking, cubic when enlarging."""
    if image.shape[1] == size:
        return image
    interpolation = cv2.INTER_AREA if image.shape[1] > size else cv2.INTER_CUBIC
    return np.stack([cv2.resize(band, (size, size), interpolation=interpolation) for band in image])
