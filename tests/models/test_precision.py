"""``--precision bfloat16``: the FPN under bfloat16 autocast, float32 maps out, and a clear
word where the hardware cannot do it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from csboundary.errors import InputError, InputWarning
from csboundary.models.device import bfloat16_hardware, cpuinfo_value
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.models.maps import predict_probabilities
from helpers import run_cli


@pytest.fixture(scope="module")
def small_fpn():
    torch.manual_seed(0)
    return FPN(FPNConfig(widths=(8, 16, 16, 16), pyramid=8, stem=8)).eval()


def test_bfloat16_maps_are_float32_probabilities_near_the_float32_ones_but_not_equal(small_fpn):
    image = np.random.default_rng(1).integers(0, 256, (2, 4, 96, 96), dtype=np.uint8)
    full = predict_probabilities(small_fpn, image, torch.device("cpu"))
    half = predict_probabilities(small_fpn, image, torch.device("cpu"), "bfloat16")
    assert half.dtype == np.float32 and half.shape == full.shape
    assert 0.0 <= half.min() and half.max() <= 1.0
    difference = np.abs(half - full).max()
    assert 0.0 < difference < 0.1  # bfloat16 arithmetic did run (an 8-bit mantissa), and stayed close
    assert next(small_fpn.parameters()).dtype == torch.float32  # the weights were not converted


@pytest.mark.parametrize(
    "flags, expected",
    [
        ("fpu sse avx2 avx512f", False),
        ("fpu avx512f avx512_bf16", True),
        ("fpu amx_bf16 amx_tile", True),
        ("fpu avx512_bf16x", False),  # a whole flag, not a prefix
    ],
)
def test_bfloat16_hardware_reads_the_cpu_flags(tmp_path, flags, expected):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(
        f"processor\t: 0\nmodel name\t: Some CPU\nflags\t\t: {flags}\n\nprocessor\t: 1\nflags\t\t: {flags}\n"
    )
    assert bfloat16_hardware(torch.device("cpu"), str(cpuinfo)) is expected
    assert bfloat16_hardware(torch.device("cpu"), str(tmp_path / "missing")) is False
    assert cpuinfo_value("model name", str(cpuinfo)) == "Some CPU"  # the first processor's, spaces trimmed
    assert cpuinfo_value("microcode", str(cpuinfo)) is None


def test_the_predictor_refuses_unknown_precisions_and_warns_without_bfloat16_units(monkeypatch):
    import csboundary.pipeline.prediction.patch as patch_module
    from csboundary.pipeline.prediction.patch import PatchPredictor

    predictor = PatchPredictor.load(None, torch.device("cpu"))
    with pytest.raises(InputError, match="unknown precision 'half'"):
        predictor.use_precision("half")
    monkeypatch.setattr(patch_module, "bfloat16_hardware", lambda device: False)
    with pytest.warns(InputWarning, match="no bfloat16 units"):
        predictor.use_precision("bfloat16")
    assert predictor.precision == "bfloat16"
    monkeypatch.setattr(patch_module, "bfloat16_hardware", lambda device: True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        predictor.use_precision("float32")
        predictor.use_precision("bfloat16")


def test_the_command_line_names_a_wrong_precision(tmp_path):
    done = run_cli("demo", "--out", str(tmp_path / "demo"), "--precision", "fp8")
    assert done.returncode == 2 and "error: --precision: unknown precision 'fp8'" in done.stderr
    assert not (tmp_path / "demo" / "prediction").exists()
