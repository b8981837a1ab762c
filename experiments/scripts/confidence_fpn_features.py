"""Experiment: does the FPN's own pyramid, pooled along each edge, make the edge confidence
better on real imagery? (issue 54; docs/experiments.md "Edge confidence from the FPN's features").

For every city: predict it with the bundle (its evidence and labels, as fit-confidence does), run
the bundle's FPN (PyTorch) over the whole image in the model's frame up to its fused pyramid
(``pyramid`` channels at the encoder's stride 4), and pool the pyramid along each edge and 6 px to
either side (mean along, mean absolute side difference). The pooled vectors are projected on their
first ``--components`` principal axes, fitted on the fitting cities' edges; confidence models are
fitted with and without those columns and scored on every other set.

    .venv/bin/python experiments/scripts/confidence_fpn_features.py --cache DIR fit=data/conf-fit/* ottawa=/tmp/ottawa nyc=/tmp/nyc ...
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).parent))
from confidence_image import model_image  # noqa: E402

from csboundary.data import city as layout  # noqa: E402
from csboundary.graph.chains import edge_line  # noqa: E402
from csboundary.graph.edge_evidence import FEATURES  # noqa: E402
from csboundary.graph.polyline import points_along  # noqa: E402
from csboundary.metrics.confidence import TRUE_SHARE, confidence_report  # noqa: E402
from csboundary.models.fpn import top_down  # noqa: E402
from csboundary.pipeline.evaluation.evaluate_set import set_cities  # noqa: E402
from csboundary.pipeline.prediction.patch import load_predictor  # noqa: E402
from csboundary.pipeline.training.confidence_fit import TREE_SHARE, city_edges  # noqa: E402

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
        side = np.abs(_at(features, pts + SIDE_PX * nrm, stride) - _at(features, pts - SIDE_PX * nrm, stride)).mean(axis=1)
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
    np.savez(target, evidence=evidence, fpn=pooled(edges.graph, features, stride), truth_share=edges.truth_share,
             length=edges.graph.edge_lengths())
    print(f"{target.name}: {edges.graph.n_edges} edges", flush=True)
    return target


def load(files: list[Path]) -> dict[str, np.ndarray]:
    parts = [dict(np.load(f)) for f in files]
    parts = [p for p in parts if len(p["truth_share"])]
    out = {k: np.concatenate([p[k] for p in parts]) for k in ("evidence", "fpn", "truth_share", "length")}
    out["group"] = np.concatenate([np.full(len(p["truth_share"]), k) for k, p in enumerate(parts)])
    return out


def fit_model(x: np.ndarray, fit: dict):
    """Trees and isotonic map as fit-confidence fits them (confidence_image.fit_model), on every column of ``x``."""
    from sklearn.ensemble import GradientBoostingClassifier
    from sklearn.isotonic import IsotonicRegression
    from sklearn.model_selection import GroupKFold

    positive, tree_positive, groups = fit["truth_share"] >= TRUE_SHARE, fit["truth_share"] >= TREE_SHARE, fit["group"]
    make = lambda: GradientBoostingClassifier(n_estimators=200, max_depth=2, learning_rate=0.05, random_state=0)  # noqa: E731
    raw = np.zeros(len(x))
    for train, test in GroupKFold(n_splits=min(5, len(np.unique(groups)))).split(x, positive, groups):
        raw[test] = make().fit(x[train], tree_positive[train]).decision_function(x[test])
    iso = IsotonicRegression(out_of_bounds="clip", y_min=0, y_max=1).fit(raw, positive)
    trees = make().fit(x, tree_positive)
    return lambda z: iso.predict(trees.decision_function(z))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("sets", nargs="+", help="NAME=PATH[,PATH...]: set folders or city directories; the first is fitted on")
    parser.add_argument("--cache", type=Path, required=True)
    parser.add_argument("--weights", type=Path, default=None)
    parser.add_argument("--components", type=int, nargs="+", default=[4, 8, 16])
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(2)
    predictor = load_predictor(args.weights, "cpu")
    sets = {}
    for item in args.sets:
        name, paths = item.split("=", 1)
        cities = []
        for path in map(Path, sum((glob.glob(p) for p in paths.split(",")), [])):
            cities += [path] if layout.is_city_dir(path) else set_cities(path)
        sets[name] = [city_record(c, predictor, args.cache, name) for c in cities]
    names = list(sets)
    fit = load(sets[names[0]])
    from sklearn.decomposition import PCA

    finite = np.isfinite(fit["evidence"]).all(axis=0)
    columns = {"shipped features": lambda d: d["evidence"][:, finite]}
    for k in args.components:
        pca = PCA(n_components=k, random_state=0).fit((fit["fpn"] - fit["fpn"].mean(0)) / (fit["fpn"].std(0) + 1e-6))
        scale = (fit["fpn"].mean(0), fit["fpn"].std(0) + 1e-6)
        columns[f"+ fpn pca{k}"] = (lambda pca, scale: lambda d: np.concatenate(
            [d["evidence"][:, finite], pca.transform((d["fpn"] - scale[0]) / scale[1])], axis=1))(pca, scale)
    models = {label: (make, fit_model(make(fit), fit)) for label, make in columns.items()}
    print(f"fitted on {len(fit['length'])} edges of {len(sets[names[0]])} cities")
    print(f"{'set':24s} {'edges':>6s} " + "".join(f"{label + ' AUC':>24s}{'ECE':>7s}" for label in models))
    for name in names[1:]:
        d = load(sets[name])
        row = f"{name:24s} {len(d['length']):6d} "
        for label, (make, model) in models.items():
            r = confidence_report(model(make(d)), d["truth_share"], d["length"])
            row += f"{r['auc']:24.3f}{r['ece']:7.3f}"
        print(row, flush=True)


if __name__ == "__main__":
    main()
