"""The FPN in 8-bit integers on ONNX Runtime (``--precision int8``): 2.5-2.8x faster than float32 on
a CPU with VNNI or AMX units, with probabilities that move by about 0.001 on average.

ONNX Runtime's static quantization stores each convolution's weights as int8 (one scale per
output channel) and each activation as uint8 with a scale and zero point fixed beforehand by
calibration: the float network runs on a few windows and the range of every activation is
recorded (min/max). Those windows are rendered by the project's own synthetic generator (training
split, one per training style, fixed seed), each also as RGB imagery is read (NIR := green) and
re-lit by the training's photometric augmentation (seeded), so that activations of real RGB
photographs fall inside the calibrated ranges; never the user's imagery or the real validation
crops, so the quantized network is made from the weights file and these fixed windows alone, and
is cached beside the float export under the weights' hash.
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import numpy as np

from csboundary.models.onnx_session import WINDOW

# the styles of the shipped FPN's training mix (csboundary/weights/fpn-config.json): calibration
# sees each once, so no activation range is set by one kind of city alone
CALIBRATION_STYLES = ("classic", "grid", "downtown", "suburb", "rural", "irregular", "residential", "leafy", "dense")
CALIBRATION_SEED = 0  # training-split city of each style; the windows are the same on every machine
QUANTIZATION_VERSION = 3  # in the cached file's name: bump when the calibration or the settings change


def calibration_windows(
    styles: tuple[str, ...] | None = None, seed: int = CALIBRATION_SEED, real_looks: bool = True
) -> list[np.ndarray]:
    """One rendered (4, 1100, 1100) uint8 window of a training-split synthetic city per style
    (default: ``CALIBRATION_STYLES``); with ``real_looks``, each also with NIR := green (how RGB
    photographs are read) and re-lit (every other one of those with NIR := green). Without them
    int8 lost precision@5 on the real sets (Ottawa -0.018, NYC -0.061 against float32); with
    them it is within their noise (docs/cpu-inference.md)."""
    from csboundary.data.synth.city import plan_city
    from csboundary.data.synth.styles import style_config

    styles = CALIBRATION_STYLES if styles is None else styles
    windows = [plan_city(style_config(style, tile_size=WINDOW), "train", seed, (1, 1)).render(0, 0) for style in styles]
    if not real_looks:
        return windows
    rng = np.random.default_rng(seed)
    rgb = [nir_as_green(w) for w in windows]
    return windows + rgb + [relit(rgb[k] if k % 2 else w, rng) for k, w in enumerate(windows)]


def nir_as_green(window: np.ndarray) -> np.ndarray:
    """A (4, h, w) window as RGB imagery is read: its NIR band replaced by green."""
    out = window.copy()
    out[3] = out[1]
    return out


def relit(window: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A uint8 window re-lit, re-coloured and degraded as training augments (seeded ``rng``)."""
    from csboundary.models.augmentation import AugmentConfig, photometric

    x = photometric(rng, window.astype(np.float32) / 255.0, AugmentConfig())
    return np.clip(np.rint(x * 255.0), 0, 255).astype(np.uint8)


class _Windows:
    """ONNX Runtime's calibration reader: one window at a time, as the FPN's input."""

    def __init__(self, windows: list[np.ndarray]):
        from csboundary.models.maps import unit_bands

        self._inputs = iter([{"image": unit_bands(w[None]).astype(np.float32)} for w in windows])

    def get_next(self):
        return next(self._inputs, None)

    def rewind(self):  # part of the reader protocol; calibration reads the windows once
        pass


def quantize_fpn(model: bytes, windows: list[np.ndarray] | None = None) -> bytes:
    """The float32 FPN export ``model`` -> the same network with int8 weights (per output channel)
    and uint8 activations calibrated on ``windows`` (default: :func:`calibration_windows`)."""
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    windows = calibration_windows() if windows is None else windows
    previous = logging.getLogger().level
    logging.getLogger().setLevel(logging.ERROR)  # the quantizer logs advice at INFO/WARNING on the root logger
    try:
        with tempfile.TemporaryDirectory(prefix="csboundary-int8-") as tmp:
            source, prepared, quantized = (Path(tmp) / name for name in ("fpn.onnx", "prepared.onnx", "int8.onnx"))
            source.write_bytes(model)
            quant_pre_process(str(source), str(prepared), skip_symbolic_shape=True)  # shapes and folded constants
            quantize_static(
                str(prepared),
                str(quantized),
                _Windows(windows),
                quant_format=QuantFormat.QDQ,
                per_channel=True,
                activation_type=QuantType.QUInt8,
                weight_type=QuantType.QInt8,
                calibrate_method=CalibrationMethod.MinMax,
            )
            return quantized.read_bytes()
    finally:
        logging.getLogger().setLevel(previous)
