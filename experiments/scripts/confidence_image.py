"""Experiment: does evidence read from the image itself make the edge confidence better on real
imagery? (issue 54; docs/experiments.md "Edge confidence from the image").

For every city: predict it with the bundle (its evidence and labels, as fit-confidence does) and
read, along each edge and to either side, image statistics in the model's frame: gradient
strength and its alignment with the edge's normal, the grey and colour step across the edge,
greenness and texture on either side. Each statistic is divided by its city-wide median or
spread, so a darker or sharper photograph does not shift it. Then confidence models are fitted
on the fitting cities with and without the image columns and scored on every other set.

    .venv/bin/python experiments/scripts/confidence_image.py --cache DIR fit=SET_OR_CITIES... ottawa=/tmp/ottawa nyc=/tmp/nyc ...

The first NAME is the fitting set. Cities already in the cache are not predicted again.
"""

from __future__ import annotations

import argparse
import glob
import warnings
from pathlib import Path

import cv2
import numpy as np

from csboundary.data import city_layout
from csboundary.data.inputs import open_imagery
from csboundary.data.model_view import model_view
from csboundary.graph.chains import edge_line
from csboundary.graph.edge_evidence import FEATURES
from csboundary.graph.polyline import points_along
from csboundary.metrics.confidence_quality import TRUE_SHARE, confidence_report
from csboundary.pipeline.prediction.city_scores import set_cities
from csboundary.pipeline.prediction.patch import load_predictor
from csboundary.pipeline.training.confidence_fit import TREE_SHARE, city_edges

IMAGE_FEATURES = (
    "img_grad_on",
    "img_grad_across",
    "img_align",
    "img_step",
    "img_color_step",
    "img_step_far",
    "img_green_high",
    "img_green_low",
    "img_texture_high",
    "img_texture_low",
)


def image_channels(rgb: np.ndarray, valid: np.ndarray) -> dict[str, np.ndarray]:
    """Per-pixel statistics of an (3, H, W) uint8 image, normalised city-wide."""
    rgb = rgb.astype(np.float32) / 255.0
    gray = rgb.mean(axis=0)
    smooth = cv2.GaussianBlur(gray, (0, 0), 1.5)
    gx, gy = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)
    grad = np.hypot(gx, gy)
    mean = cv2.blur(gray, (7, 7))
    texture = np.sqrt(np.maximum(cv2.blur(gray * gray, (7, 7)) - mean * mean, 0))
    green = rgb[1] - (rgb[0] + rgb[2]) / 2
    v = valid if valid.any() else np.ones_like(valid)
    grad_scale = float(np.median(grad[v])) + 1e-4
    gray_scale = float(np.std(gray[v])) + 1e-4
    return {
        "gx": gx / grad_scale,
        "gy": gy / grad_scale,
        "grad": grad / grad_scale,
        "gray": smooth / gray_scale,
        "rgb": rgb / gray_scale,
        "green": green / (float(np.std(green[v])) + 1e-4),
        "texture": texture / (float(np.median(texture[v])) + 1e-4),
    }


def _at(image: np.ndarray, pts: np.ndarray) -> np.ndarray:
    h, w = image.shape[-2:]
    c = np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
    r = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1)
    return image[..., r, c]


def image_evidence(graph, channels: dict[str, np.ndarray]) -> np.ndarray:
    """(E, len(IMAGE_FEATURES)) image statistics along each edge of ``graph`` (model pixels)."""
    out = np.full((graph.n_edges, len(IMAGE_FEATURES)), np.nan)
    for k in range(graph.n_edges):
        pts, nrm = points_along(edge_line(graph, k), 2.0)
        grad = _at(channels["grad"], pts)
        across = np.abs(_at(channels["gx"], pts) * nrm[:, 0] + _at(channels["gy"], pts) * nrm[:, 1])
        step = abs(np.mean(_at(channels["gray"], pts + 4 * nrm)) - np.mean(_at(channels["gray"], pts - 4 * nrm)))
        color = np.mean(
            np.linalg.norm(_at(channels["rgb"], pts + 4 * nrm) - _at(channels["rgb"], pts - 4 * nrm), axis=0)
        )
        far = abs(np.mean(_at(channels["gray"], pts + 12 * nrm)) - np.mean(_at(channels["gray"], pts - 12 * nrm)))
        green = np.sort(
            [np.mean(_at(channels["green"], pts + 6 * nrm)), np.mean(_at(channels["green"], pts - 6 * nrm))]
        )
        texture = np.sort(
            [np.mean(_at(channels["texture"], pts + 6 * nrm)), np.mean(_at(channels["texture"], pts - 6 * nrm))]
        )
        out[k] = (
            np.mean(grad),
            np.mean(across),
            np.mean(across) / (np.mean(grad) + 1e-6),
            step,
            color,
            far,
            green[1],
            green[0],
            texture[1],
            texture[0],
        )
    return out


def model_image(city: Path, predictor) -> tuple[np.ndarray, np.ndarray]:
    """A labelled city's whole imagery as the model sees it (its pixel size): (4, H, W) uint8 and valid (H, W)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mosaic, _ = open_imagery([city])
        view = model_view(mosaic, model_gsd=predictor.pixel_size_m, assume_model_gsd=True)
    with view.mosaic as m:
        read = m.read(m.window)
    return np.asarray(read.data), np.asarray(read.valid)


def city_record(city: Path, predictor, cache: Path, prefix: str) -> Path:
    target = cache / f"{prefix}-{city.name}.npz"
    if target.exists():
        return target
    edges = city_edges(city, predictor, assume_model_gsd=True)
    data, valid = model_image(city, predictor)
    channels = image_channels(data[:3], valid)
    evidence = edges.evidence if edges.graph.n_edges else np.zeros((0, len(FEATURES)))
    np.savez(
        target,
        evidence=evidence,
        image=image_evidence(edges.graph, channels),
        truth_share=edges.truth_share,
        length=edges.graph.edge_lengths(),
    )
    print(f"{target.name}: {edges.graph.n_edges} edges", flush=True)
    return target


def named_cities(items: list[str]) -> dict[str, list[Path]]:
    """NAME=PATH[,PATH...] (globs; set folders or city directories) -> the cities of each name, in order."""
    sets = {}
    for item in items:
        name, paths = item.split("=", 1)
        cities = []
        for path in map(Path, sum((glob.glob(p) for p in paths.split(",")), [])):
            cities += [path] if city_layout.is_city_dir(path) else set_cities(path)
        sets[name] = cities
    return sets


def load(files: list[Path], columns: tuple[str, ...] = ("evidence", "image")) -> dict[str, np.ndarray]:
    """The cached records of ``files`` concatenated (edges without truth dropped), with each edge's city as its group."""
    parts = [dict(np.load(f)) for f in files]
    parts = [p for p in parts if len(p["truth_share"])]
    out = {k: np.concatenate([p[k] for p in parts]) for k in (*columns, "truth_share", "length")}
    out["group"] = np.concatenate([np.full(len(p["truth_share"]), k) for k, p in enumerate(parts)])
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument(
        "sets", nargs="+", help="NAME=PATH[,PATH...]: set folders or city directories; the first is fitted on"
    )
    parser.add_argument("--cache", type=Path, required=True)
    parser.add_argument("--weights", type=Path, default=None)
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    predictor = load_predictor(args.weights, "cpu")
    sets = {
        name: [city_record(c, predictor, args.cache, name) for c in cities]
        for name, cities in named_cities(args.sets).items()
    }
    names = list(sets)
    fit = load(sets[names[0]])
    with_image = lambda d: np.concatenate([d["evidence"], d["image"]], axis=1)  # noqa: E731
    models = {}
    for label, extra in (("shipped features", ()), ("+ image", IMAGE_FEATURES)):
        feats = FEATURES + extra
        models[label] = (feats, fit_model(with_image(fit), fit, feats))
    print(f"fitted on {len(fit['length'])} edges of {len(sets[names[0]])} cities")
    print(f"{'set':24s} {'edges':>6s} " + "".join(f"{label + ' AUC':>22s}{'ECE':>7s}" for label in models))
    for name in names[1:]:
        d = load(sets[name])
        x = with_image(d)
        row = f"{name:24s} {len(d['length']):6d} "
        for _label, (_feats, model) in models.items():
            p = model(x)
            r = confidence_report(p, d["truth_share"], d["length"])
            row += f"{r['auc']:22.3f}{r['ece']:7.3f}"
        print(row, flush=True)


def fit_model(x: np.ndarray, fit: dict, feats: tuple[str, ...]):
    """Trees and isotonic map as fit-confidence fits them, on the columns ``feats`` of ``x``."""
    keep = [i for i, f in enumerate(FEATURES + IMAGE_FEATURES) if f in feats and np.isfinite(x[:, i]).all()]
    model = fit_trees(x[:, keep], fit)
    return lambda z: model(z[:, keep])


def fit_trees(x: np.ndarray, fit: dict):
    """Trees and isotonic map as fit-confidence fits them, on every column of ``x`` (the rows of ``fit``)."""
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


if __name__ == "__main__":
    main()
