"""Probe: self-training thins the maps (precision up, recall and APLS down; docs/adapt.md). Does a
label-free correction restore the amount of boundary while keeping where the adapted network puts
it? Per output channel, an affine map of the adapted FPN's logits (a x + b) is fitted so that its
upper quantiles on the adaptation imagery match the base FPN's on the same imagery; it is baked
into the last convolutions, so the bundle is like any other. Held-out cities are then scored.

    .venv/bin/python experiments/scripts/probe_adapt_rescale.py RUN_DIR --set /tmp/ottawa [--fold fold-0 ...]

RUN_DIR is an adapt_eval.py folder (its fold-*/adapted.pt and scores.json: which cities it
adapted on and which it holds out).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from csboundary.metrics.compare import paired_bootstrap
from csboundary.models.checkpoint import load_checkpoint, save_checkpoint, shipped_weights
from csboundary.models.maps import predict_probabilities
from csboundary.pipeline.prediction.patch import PatchPredictor

QUANTILES = (0.9, 0.95, 0.98, 0.99, 0.995, 0.998)
LAST = {
    0: ("head.1.weight", "head.1.bias", 0),
    1: ("head.1.weight", "head.1.bias", 1),
    2: ("surface_head.2.weight", "surface_head.2.bias", 0),
}


def logits(predictor: PatchPredictor, city: Path) -> np.ndarray:
    """(C, N) logits of the valid pixels of a city's imagery, in the model's frame."""
    from confidence_image import model_image  # a sibling script (main puts this folder on the path)

    data, valid = model_image(city, predictor)
    p = predict_probabilities(predictor.fpn, data, torch.device("cpu"))
    p = np.clip(p[:, valid], 1e-6, 1 - 1e-6)
    return np.log(p / (1 - p))


def main() -> None:
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from adapt_eval import city_scores  # the same scoring as the adaptation's own report

    parser = argparse.ArgumentParser()
    parser.add_argument("run", type=Path)
    parser.add_argument("--set", type=Path, required=True)
    parser.add_argument("--channels", default="0,1,2")
    args = parser.parse_args()
    base_path = shipped_weights()
    base = PatchPredictor.load(base_path, torch.device("cpu"))
    channels = [int(c) for c in args.channels.split(",")]
    before, after, adapted_scores = {}, {}, {}
    for fold in sorted(args.run.glob("fold-*")):
        record = json.loads((fold / "scores.json").read_text())
        adapted_path = fold / "adapted.pt"
        adapted = PatchPredictor.load(adapted_path, torch.device("cpu"))
        xb = np.concatenate([logits(base, args.set / n) for n in record["train"]], axis=1)
        xa = np.concatenate([logits(adapted, args.set / n) for n in record["train"]], axis=1)
        payload = load_checkpoint(adapted_path, ("bundle",))
        state = payload["fpn"]
        for c in channels:
            qb, qa = np.quantile(xb[c], QUANTILES), np.quantile(xa[c], QUANTILES)
            a, b = np.polyfit(qa, qb, 1)
            print(
                f"{fold.name} channel {c}: adapted quantiles {np.round(qa, 2)} base {np.round(qb, 2)} -> a {a:.3f} b {b:+.3f}"
            )
            w, bias, row = LAST[c]
            state[w][row] *= float(a)
            state[bias][row] = float(a) * state[bias][row] + float(b)
        out = fold / "rescaled.pt"
        save_checkpoint(out, "bundle", **{k: v for k, v in payload.items() if k not in ("format", "kind")})
        held = [args.set / n for n in record["held_out"]]
        scores = city_scores(held, out, 0)
        for n in record["held_out"]:
            before[n] = record["base"][n]["metrics"]
            adapted_scores[n] = record["adapted"][n]["metrics"]
            after[n] = scores[n]["metrics"]
    names = sorted(before)
    print(f"{'':12s}{'base':>8s}{'adapted':>8s}{'rescaled':>9s}{'gain':>8s}   95 % interval of rescaled - base")
    for metric in ("f1@5", "precision@5", "recall@5", "apls", "tlts"):
        a = [before[n][metric] for n in names]
        m = [adapted_scores[n][metric] for n in names]
        b = [after[n][metric] for n in names]
        diff, low, high, _ = paired_bootstrap(a, b, seed=0)
        print(
            f"{metric:12s}{np.mean(a):8.3f}{np.mean(m):8.3f}{np.mean(b):9.3f}{diff:+8.3f}   [{low:+.3f}, {high:+.3f}]"
        )


if __name__ == "__main__":
    main()
