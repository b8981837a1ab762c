"""Experiment: int8 variants of the shipped FPN against its float32 ONNX export, window by window.

    .venv/bin/python experiments/scripts/int8_variants.py --out runs/int8 [--variants current,exclude-head,...]

Windows (1100 px): one test-split window (seed 7) of every synthetic style, and the real sets'
(the 14 Ottawa crops in /tmp/ottawa and the dense-urban NYC patch; validation only). For each
variant: the mean absolute difference of every output probability from float32, the share of
pixels whose keypoint or boundary probability crosses 0.5, the same per set, and the FPN's time
per window on this machine's threads. Quantized models are kept in OUT for the end-to-end runs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from noisy_city import with_noise  # experiments/scripts/, beside this script

from csboundary.models.maps import unit_bands
from csboundary.models.onnx_quantization import CALIBRATION_STYLES, calibration_windows

TEST_STYLES = CALIBRATION_STYLES + ("highway",)
NYC = Path("../shared/data/real/nyc-topo-boundary/000180_31_image.tif")


def test_windows() -> dict[str, list[np.ndarray]]:
    from csboundary.data.raster import Mosaic
    from csboundary.data.synth.city import plan_city
    from csboundary.data.synth.styles import style_config
    from csboundary.data.windows import PixelWindow

    sets = {
        "synthetic": [plan_city(style_config(s, tile_size=1100), "test", 7, (1, 1)).render(0, 0) for s in TEST_STYLES]
    }

    def window(path) -> np.ndarray:
        with Mosaic.open(path) as m:
            read = m.read(PixelWindow(0, 0, 1100, 1100))
            return np.where(read.valid[None], read.data, 0).astype(np.uint8)

    ottawa = sorted(Path("/tmp/ottawa").glob("*/tiles"))
    if ottawa:
        sets["ottawa"] = [window(p) for p in ottawa]
    if NYC.exists():
        sets["nyc"] = [window(NYC)]
    return sets


def session(model: bytes, threads: int):
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    return ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])


def probabilities(sess, windows: list[np.ndarray]) -> tuple[list[np.ndarray], float]:
    out, start = [], time.perf_counter()
    for w in windows:
        logits = sess.run(None, {"image": unit_bands(w[None]).astype(np.float32)})[0][0]
        out.append(1 / (1 + np.exp(-logits)))
    return out, (time.perf_counter() - start) / len(windows)


def quantize(model: bytes, windows, exclude=(), method="minmax", extra: dict | None = None) -> bytes:
    import logging
    import tempfile

    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    from csboundary.models.onnx_quantization import _Windows

    methods = {
        "minmax": CalibrationMethod.MinMax,
        "percentile": CalibrationMethod.Percentile,
        "entropy": CalibrationMethod.Entropy,
    }
    logging.getLogger().setLevel(logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        source, prepared, quantized = (Path(tmp) / n for n in ("f.onnx", "p.onnx", "q.onnx"))
        source.write_bytes(model)
        quant_pre_process(str(source), str(prepared), skip_symbolic_shape=True)
        quantize_static(
            str(prepared),
            str(quantized),
            _Windows(windows),
            quant_format=QuantFormat.QDQ,
            per_channel=True,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            calibrate_method=methods[method],
            nodes_to_exclude=list(exclude),
            extra_options=extra or {},
        )
        return quantized.read_bytes()


def conv_names(model: bytes) -> list[str]:
    import onnx

    return [n.name for n in onnx.load_from_string(model).graph.node if n.op_type == "Conv"]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--variants",
        default="current,exclude-head,exclude-head-stem,exclude-decoder,percentile,calib3",
        help="also qat (with --qat) and float32-noiseA: float32 on windows with +-A grey levels of noise",
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--qat",
        type=Path,
        default=None,
        help="variant qat: the folded FPN of int8_qat.py, quantized as the product quantizes",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    from csboundary.pipeline.prediction.patch import load_predictor

    model = load_predictor(None, "cpu", engine="onnx").onnx.fpn_model  # the float32 export the engine runs
    convs = conv_names(model)
    head = [n for n in convs if n.startswith(("/head", "/surface_head"))]
    stem = [convs[0]]
    decoder = [n for n in convs if not n.startswith("/encoder")]
    calib = calibration_windows()
    variants = {
        "current": lambda: quantize(model, calib),
        "exclude-head": lambda: quantize(model, calib, head),
        "exclude-head-stem": lambda: quantize(model, calib, head + stem),
        "exclude-decoder": lambda: quantize(model, calib, decoder),
        "percentile": lambda: quantize(model, calib, (), "percentile"),
        "calib3": lambda: quantize(model, calib + calibration_windows(seed=1) + calibration_windows(seed=2)),
        "calib3-exclude-head": lambda: quantize(
            model, calib + calibration_windows(seed=1) + calibration_windows(seed=2), head
        ),
    }

    def qat_model() -> bytes:
        import torch

        from csboundary.models.batchnorm_folding import fold_batch_norms
        from csboundary.models.fpn import fpn_for_weights
        from csboundary.models.onnx_engine import export_fpn

        saved = torch.load(args.qat, map_location="cpu", weights_only=True)
        folded = fold_batch_norms(fpn_for_weights(saved["config"]))
        folded.load_state_dict(saved["state_dict"])
        return quantize(export_fpn(folded), calib)

    variants["qat"] = qat_model
    sets = test_windows()
    reference = {name: probabilities(session(model, args.threads), ws) for name, ws in sets.items()}
    report = {"float32_s_per_window": {k: round(v[1], 3) for k, v in reference.items()}, "variants": {}}
    print(f"float32: {report['float32_s_per_window']} s per window", flush=True)
    for name in args.variants.split(","):
        noise = name.startswith("float32-noise")  # float32 on the windows with +-A grey levels of noise: the floor
        if noise:
            sess = session(model, args.threads)
        else:
            path = args.out / f"fpn-int8-{name}.onnx"
            if not path.exists():
                path.write_bytes(variants[name]())
            sess = session(path.read_bytes(), args.threads)
        row = {}
        for set_name, windows in sets.items():
            if noise:
                amplitude, rng = int(name.removeprefix("float32-noise")), np.random.default_rng(0)
                windows = [with_noise(w, amplitude, rng) for w in windows]
            probs, seconds = probabilities(sess, windows)
            diff = np.concatenate(
                [np.abs(p - q).reshape(len(p), -1) for p, q in zip(probs, reference[set_name][0])], axis=1
            )
            cross = np.concatenate(
                [((p[:2] > 0.5) != (q[:2] > 0.5)).reshape(2, -1) for p, q in zip(probs, reference[set_name][0])], axis=1
            )
            row[set_name] = {
                "mean_abs_diff": [round(float(d), 5) for d in diff.mean(axis=1)],
                "cross_0.5": [round(float(c), 5) for c in cross.mean(axis=1)],
                "s_per_window": round(seconds, 3),
            }
        report["variants"][name] = row
        print(name, json.dumps(row), flush=True)
    (args.out / "report.json").write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
