"""Probe: int8 loses precision on real photographs (Ottawa P@5 -0.018, NYC -0.061 against float32)
while synthetic cities barely move. Real RGB imagery is read with NIR := green, which the
calibration windows (synthetic, with their own NIR band) never show. Does calibrating on those
windows also with NIR := green, or also re-lit, bring int8 back to float32 on the real sets?

    .venv/bin/python experiments/scripts/probe_int8_calibration.py SET... [--variants current,nir,nir+photo]

Each variant quantizes the shipped FPN's float export on its windows and scores every SET with
``evaluate-set``'s rules (mean over cities), beside float32.
"""

from __future__ import annotations

import argparse

import numpy as np

from csboundary.models.onnx_quantization import calibration_windows, nir_as_green, quantize_fpn
from csboundary.pipeline.evaluation.evaluate_set import evaluate_set
from csboundary.pipeline.prediction.patch import load_predictor

SHOWN = ("precision@5", "recall@5", "f1@5", "apls", "tlts")


def variant_windows(name: str) -> list[np.ndarray]:
    """``current``: the synthetic windows alone (the calibration before); ``nir``: also each with
    NIR := green; ``nir+photo``: the product's calibration (also re-lit)."""
    if name == "current":
        return calibration_windows(real_looks=False)
    if name == "nir":
        base = calibration_windows(real_looks=False)
        return base + [nir_as_green(w) for w in base]
    if name == "nir+photo":
        return calibration_windows()
    raise ValueError(name)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("sets", nargs="+")
    parser.add_argument("--variants", default="current,nir,nir+photo")
    args = parser.parse_args()
    rows = {}
    f32 = load_predictor(None, "cpu", precision="float32", engine="onnx")
    rows["float32"] = {s: evaluate_set(s, f32, progress=False)["mean"] for s in args.sets}
    for name in args.variants.split(","):
        model = load_predictor(None, "cpu", precision="int8", engine="onnx")
        if name != "nir+photo":  # the cached int8 FPN is the product's calibration
            model.onnx.fpn_int8_model = quantize_fpn(model.onnx.fpn_model, variant_windows(name))
            model.onnx._sessions.clear()
        rows[f"int8 {name}"] = {s: evaluate_set(s, model, progress=False)["mean"] for s in args.sets}
    for s in args.sets:
        print(f"{s}: " + " ".join(f"{m:>12s}" for m in SHOWN))
        for label, per_set in rows.items():
            print(f"  {label:18s}" + "".join(f"{per_set[s][m]:12.3f}" for m in SHOWN), flush=True)


if __name__ == "__main__":
    main()
