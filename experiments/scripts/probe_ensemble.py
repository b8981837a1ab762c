"""Scores of a bundle whose keypoint and boundary maps are the mean of its own FPN's and other
FPNs' probabilities: a probe of whether averaging differently trained FPNs helps on imagery
unlike the generator's (docs/real-imagery.md). PyTorch engine; every other setting the bundle's.

    python experiments/scripts/probe_ensemble.py WEIGHTS SET_OR_CITY... [--with FPN[,FPN...]] [--views 1..8] [--vertex-threshold T]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import torch
from sweep_edge_support import score_row

import csboundary.pipeline.prediction.patch as patch_module
from csboundary.models.checkpoint import load_fpn
from csboundary.models.fpn import SURFACE
from csboundary.pipeline.prediction.patch import PatchPredictor


def averaged_probabilities(others, single):
    """A drop-in for ``predict_probabilities``: the keypoint and boundary channels averaged over
    the bundle's FPN and ``others`` (extra channels, e.g. the surface, from the bundle's FPN)."""

    def predict(model, image, device):
        probs = single(model, image, device)
        extra = [single(m, image, device)[..., :SURFACE, :, :] for m in others]
        probs[..., :SURFACE, :, :] = np.mean([probs[..., :SURFACE, :, :], *extra], axis=0)
        return probs

    return predict


def flipped_probabilities(single, turns: int):
    """A drop-in for ``predict_probabilities``: the mean over the image and its ``turns`` - 1
    other dihedral views (quarter turns, then their mirror images), each mapped back."""

    def predict(model, image, device):
        views = [(k, m) for m in (False, True) for k in range(4)][:turns]
        total = 0
        for k, mirror in views:
            view = np.rot90(image[..., ::-1] if mirror else image, k, axes=(-2, -1))
            probs = np.rot90(single(model, np.ascontiguousarray(view), device), -k, axes=(-2, -1))
            total = total + (probs[..., ::-1] if mirror else probs)
        return np.ascontiguousarray(total / len(views), dtype=np.float32)

    return predict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("sets", nargs="+")
    parser.add_argument("--with", dest="others", default="", help="comma-separated FPN checkpoints averaged in")
    parser.add_argument(
        "--vertex-threshold", default="", help="keypoint probabilities of vertex extraction (default: the bundle's)"
    )
    parser.add_argument("--views", type=int, default=1, help="dihedral views averaged (1 = the image only, up to 8)")
    args = parser.parse_args()
    device = torch.device("cpu")
    predictor = PatchPredictor.load(args.weights, device)
    predictor.onnx = None
    others = [load_fpn(path, device) for path in args.others.split(",") if path]
    single = patch_module.predict_probabilities
    if args.views > 1:
        single = flipped_probabilities(single, args.views)
    patch_module.predict_probabilities = averaged_probabilities(others, single)
    for vthr in (
        [float(v) for v in args.vertex_threshold.split(",")]
        if args.vertex_threshold
        else [predictor.settings.vertices.threshold]
    ):
        predictor.settings = dataclasses.replace(
            predictor.settings, vertices=dataclasses.replace(predictor.settings.vertices, threshold=vthr)
        )
        print(
            f"with {len(others)} FPNs, vertex threshold {vthr:g}: F1@5/APLS/TLTS "
            + " ".join(score_row(args.sets, predictor)),
            flush=True,
        )


if __name__ == "__main__":
    main()
