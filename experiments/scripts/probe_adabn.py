"""Scores of a bundle whose FPN batch norms use each window's own statistics (AdaBN, Li et al.
2016) instead of the training cities': a probe of test-time adaptation to imagery unlike the
generator's (docs/real-imagery.md).

    python experiments/scripts/probe_adabn.py WEIGHTS SET_OR_CITY... [--scope off|encoder|all] [--vertex-threshold T]

The statistics are the window's own, so neighbouring windows of a city are normalised
differently: a probe for one-window sets such as the Ottawa crops, not a pipeline option.
PyTorch engine; every other setting is the bundle's.
"""

from __future__ import annotations

import argparse
import dataclasses

import torch
from sweep_edge_support import score_row

import csboundary.pipeline.prediction.patch as patch_module
from csboundary.models.maps import image_tensor
from csboundary.pipeline.prediction.patch import PatchPredictor


def window_statistics_probabilities(scope: str):
    """A drop-in for ``predict_probabilities`` whose batch norms in ``scope`` (the encoder or the
    whole FPN) normalise by the input's statistics; the stored statistics are left unchanged."""

    def predict(model, image, device):
        model.eval()
        norms = [
            m for m in (model.encoder if scope == "encoder" else model).modules() if isinstance(m, torch.nn.BatchNorm2d)
        ]
        stored = [(m.running_mean.clone(), m.running_var.clone()) for m in norms]
        for m in norms:
            m.train()
        batch = image_tensor(image, device)
        with torch.no_grad():
            probs = torch.sigmoid(model(batch if batch.ndim == 4 else batch[None])).float().cpu().numpy()
        for m, (mean, var) in zip(norms, stored):
            m.running_mean.copy_(mean)
            m.running_var.copy_(var)
            m.eval()
        return probs if batch.ndim == 4 else probs[0]

    return predict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights")
    parser.add_argument("sets", nargs="+")
    parser.add_argument(
        "--scope", choices=("off", "encoder", "all"), default="all", help="batch norms on the window's statistics"
    )
    parser.add_argument(
        "--vertex-threshold",
        type=float,
        default=None,
        help="keypoint probability of vertex extraction (default: the bundle's)",
    )
    args = parser.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    predictor.onnx = None  # the PyTorch path, whose batch norms can be switched
    if args.vertex_threshold is not None:
        predictor.settings = dataclasses.replace(
            predictor.settings,
            vertices=dataclasses.replace(predictor.settings.vertices, threshold=args.vertex_threshold),
        )
    if args.scope != "off":
        patch_module.predict_probabilities = window_statistics_probabilities(args.scope)
    print(
        f"scope {args.scope} vertex threshold {predictor.settings.vertices.threshold:g}: F1@5/APLS/TLTS "
        + " ".join(score_row(args.sets, predictor))
    )


if __name__ == "__main__":
    main()
