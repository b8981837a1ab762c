"""Scores on a validation set when the FPN maps are averaged over flips of the input (test-time
augmentation), with the shipped weights on PyTorch: a lever measured, not shipped (docs/real-imagery.md).

    python experiments/scripts/probe_flip_tta.py 2|4   (2: identity + left-right; 4: + up-down + both), on /tmp/ottawa
"""

import sys

import numpy as np

from csboundary.pipeline.evaluation.evaluate_set import evaluate_set
from csboundary.pipeline.prediction.patch import load_predictor

flips = {"2": [(), (-1,)], "4": [(), (-1,), (-2,), (-2, -1)]}[sys.argv[1]]
p = load_predictor(device="cpu", engine="torch")
base = p.patch_maps


def tta(patches, images):
    out = None
    for axes in flips:
        imgs = [np.ascontiguousarray(np.flip(im, axis=axes)) if axes else im for im in images]
        maps = base(patches, imgs)
        maps = [np.flip(m, axis=axes) if axes else m for m in maps]
        out = maps if out is None else [a + b for a, b in zip(out, maps)]
    return [np.ascontiguousarray(m / len(flips)) for m in out]


p.patch_maps = tta
r = evaluate_set("/tmp/ottawa", p, progress=False)
m = r["mean"]
print(sys.argv[1], {k: round(m[k], 3) for k in ("precision@5", "recall@5", "f1@5", "apls", "tlts")})
