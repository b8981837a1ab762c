"""Experiment: does the FPN's own pyramid, pooled along each edge, make the edge confidence
better on real imagery? (issue 54; docs/experiments.md "Edge confidence from the FPN's features").

For every city: predict it with the bundle (its evidence and labels, as fit-confidence does), run
the bundle's FPN (PyTorch) over the whole image in the model's frame up to its fused pyramid
(``pyramid`` channels at the encoder's stride 4), and pool the pyramid along each edge and 6 px to
either side (mean along, mean absolute side difference). The pooled vectors are projected on their
first ``--components`` principal axes, fitted on the fitting cities' edges; confidence models are
fitted with and without those columns and scored on every other set.

    .venv/bin/python experiments/scripts/confidence_fpn_features.py --cache DIR fit=data/conf-fit/* ottawa=/tmp/ottawa
        nyc=/tmp/nyc ...
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).parent))
from confidence_image import fit_trees, load, model_image, named_cities  # noqa: E402

from csboundary.graph.chains import edge_line  # noqa: E402
from csboundary.graph.edge_evidence import FEATURES  # noqa: E402
from csboundary.graph.polyline import points_along  # noqa: E402
from csboundary.metrics.confidence_quality import confidence_report  # noqa: E402
from csboundary.models.fpn import top_down  # noqa: E402
from csboundary.pipeline.prediction.patch import load_predictor  # noqa: E402
from csboundary.pipeline.training.confidence_fit import city_edges  # noqa: E402

SIDE_PX = 6.0


@torch.no_grad()
def pyramid(fpn, data: np.ndarray) -> tuple[np.ndarray, float]:
    """(C, h, w) fused pyramid of the FPN over a (4, H, W) uint8 image, and its stride in image px."""
    image = torch.from_numpy(data.astype(np.float32) / 255.0)[None, : fpn.config.in_channels]
    h, w = image.shape[-2:]
    x = F.pad(image, (0, (-w) % fpn.stride, 0, (-h) % fpn.stride), mode="replicate")
    factor = round(1 / fpn.config.encoder_scale)
    small = F.avg_pool2d(x, factor) if factor > 1 else x
    fused = top_down(fpn.encoder(small)[1:], fpn.lateral, fpn.smooth)[0].numpy()
    return fused, x.shape[-1] / fused.shape[-1]


def _at(features: np.ndarray, pts: np.ndarray, stride: float) -> np.ndarray:
    h, w = features.shape[-2:]
    c = np.clip((pts[:, 0] / stride).astype(int), 0, w - 1)
    r = np.clip((pts[:, 1] / stride).astype(int), 0, h - 1)
    return features[:, r, c]


def pooled(graph, features: np.ndarray, stride: float) -> np.ndarray:
    """(E, 2C): the pyramid's mean along each edge, and the mean |left - right| 6 px out."""
    out = np.zeros((graph.n_edges, 2 * features.shape[0]), np.float32)
    for k in range(graph.n_edges):
        pts, nrm = points_along(edge_line(graph, k), 2.0)
        along = _at(features, pts, stride).mean(axis=1)
        side = np.abs(_at(features, pts + SIDE_PX * nrm, stride) - _at(features, pts - SIDE_PX * nrm, stride)).mean(
            axis=1
        )
        out[k] = np.concatenate([along, side])
    return out


def city_record(city: Path, predictor, cache: Path, prefix: str) -> Path:
    target = cache / f"fpnfeat-{prefix}-{city.name}.npz"
    if target.exists():
        return target
    edges = city_edges(city, predictor, assume_model_gsd=True)
    data, _ = model_image(city, predictor)
    features, stride = pyramid(predictor.fpn, data)
    evidence = edges.evidence if edges.graph.n_edges else np.zeros((0, len(FEATURES)))
    np.savez(
        target,
        evidence=evidence,
        fpn=pooled(edges.graph, features, stride),
        truth_share=edges.truth_share,
        length=edges.graph.edge_lengths(),
    )
    print(f"{target.name}: {edges.graph.n_edges} edges", flush=True)
    return target


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument(
        "sets", nargs="+", help="NAME=PATH[,PATH...]: set folders or city directories; the first is fitted on"
    )
    parser.add_argument("--cache", type=Path, required=True)
    parser.add_argument("--weights", type=Path, default=None)
    parser.add_argument("--components", type=int, nargs="+", default=[4, 8, 16])
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(2)
    predictor = load_predictor(args.weights, "cpu")
    sets = {
        name: [city_record(c, predictor, args.cache, name) for c in cities]
        for name, cities in named_cities(args.sets).items()
    }
    names = list(sets)
    fit = load(sets[names[0]], ("evidence", "fpn"))
    from sklearn.decomposition import PCA

    finite = np.isfinite(fit["evidence"]).all(axis=0)
    columns = {"shipped features": lambda d: d["evidence"][:, finite]}
    for k in args.components:
        pca = PCA(n_components=k, random_state=0).fit((fit["fpn"] - fit["fpn"].mean(0)) / (fit["fpn"].std(0) + 1e-6))
        scale = (fit["fpn"].mean(0), fit["fpn"].std(0) + 1e-6)
        columns[f"+ fpn pca{k}"] = (
            lambda fitted_pca, fitted_scale: (
                lambda d: np.concatenate(
                    [d["evidence"][:, finite], fitted_pca.transform((d["fpn"] - fitted_scale[0]) / fitted_scale[1])],
                    axis=1,
                )
            )
        )(pca, scale)
    models = {label: (make, fit_trees(make(fit), fit)) for label, make in columns.items()}
    print(f"fitted on {len(fit['length'])} edges of {len(sets[names[0]])} cities")
    print(f"{'set':24s} {'edges':>6s} " + "".join(f"{label + ' AUC':>24s}{'ECE':>7s}" for label in models))
    for name in names[1:]:
        d = load(sets[name], ("evidence", "fpn"))
        row = f"{name:24s} {len(d['length']):6d} "
        for _label, (make, model) in models.items():
            r = confidence_report(model(make(d)), d["truth_share"], d["length"])
            row += f"{r['auc']:24.3f}{r['ece']:7.3f}"
        print(row, flush=True)


if __name__ == "__main__":
    main()
