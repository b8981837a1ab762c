"""Probe: drop patch-graph edges that no predicted road surface borders.

    .venv/bin/python experiments/scripts/probe_surface_filter.py HEAD SETS... --rule maxside --thresholds 0,0.3,0.5

For each edge, points every pixel along its polyline, the surface probability at +-``--offset`` px
along the normal: ``maxside`` = mean over points of max(left, right); ``contrast`` = mean |left - right|.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from probe_surface import SurfaceHead, fused_features  # noqa: E402

from csboundary.data import city_layout  # noqa: E402
from csboundary.models.maps import unit_bands  # noqa: E402
from csboundary.pipeline.evaluation.evaluate_set import evaluate_set
from csboundary.pipeline.prediction.city_scores import evaluate_city_dir
from csboundary.pipeline.prediction.patch import PatchPredictor  # noqa: E402

STATE = {"rule": "maxside", "threshold": 0.0, "offset": 8.0, "low": None}


def surface_map(predictor, head, image: np.ndarray) -> np.ndarray:
    x = torch.from_numpy(unit_bands(image))[None]
    h, w = x.shape[-2:]
    x = torch.nn.functional.pad(x, (0, (-w) % 64, 0, (-h) % 64), mode="replicate")
    with torch.no_grad():
        return torch.sigmoid(head(fused_features(predictor.fpn, x), x.shape[-2:]))[0, 0, :h, :w].numpy()


def edge_stats(graph, surface: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray]:
    h, w = surface.shape
    maxside, contrast = np.ones(graph.n_edges), np.ones(graph.n_edges)
    for k in range(graph.n_edges):
        line = np.asarray(graph.edge_polyline(k), float)
        seg = np.diff(line, axis=0)
        lengths = np.linalg.norm(seg, axis=1)
        pts, normals = [], []
        for a, d, n in zip(line[:-1], seg, lengths):
            if n < 1e-6:
                continue
            m = max(2, int(np.ceil(n)) + 1)
            t = np.linspace(0, 1, m)[:, None]
            pts.append(a + d * t)
            normals.append(np.repeat([[-d[1] / n, d[0] / n]], m, axis=0))
        if not pts:
            continue
        pts, normals = np.concatenate(pts), np.concatenate(normals)

        def at(p):
            c = np.clip(np.floor(p[:, 0]).astype(int), 0, w - 1)
            r = np.clip(np.floor(p[:, 1]).astype(int), 0, h - 1)
            return surface[r, c]

        left, right = at(pts + offset * normals), at(pts - offset * normals)
        maxside[k] = np.maximum(left, right).mean()
        contrast[k] = np.abs(left - right).mean()
    return maxside, contrast


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("head")
    p.add_argument("sets", nargs="+")
    p.add_argument("--weights", default=None)
    p.add_argument("--rule", default="maxside")
    p.add_argument("--thresholds", default="0,0.3,0.5")
    p.add_argument("--offset", type=float, default=8.0)
    p.add_argument(
        "--low", type=float, default=None, help="hysteresis: keep edges >= low connected to one >= threshold"
    )
    args = p.parse_args()
    predictor = PatchPredictor.load(args.weights, torch.device("cpu"))
    head = SurfaceHead()
    head.load_state_dict(torch.load(args.head, weights_only=True))
    head.eval()
    original = PatchPredictor.connect

    def connect(self, patch, image, maps, found):
        graph = original(self, patch, image, maps, found)
        if STATE["threshold"] <= 0 or graph.n_edges == 0:
            return graph
        surface = surface_map(self, head, image)
        maxside, contrast = edge_stats(graph, surface, STATE["offset"])
        stat = maxside if STATE["rule"] == "maxside" else contrast
        if STATE["low"] is None:
            return graph.edge_subgraph(stat >= STATE["threshold"])
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        weak = stat >= STATE["low"]
        e = np.asarray(graph.edges)[weak]
        n = graph.n_vertices
        _, label = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
        strong_labels = set(label[np.asarray(graph.edges)[stat >= STATE["threshold"], 0]])
        keep = weak & np.isin(label[np.asarray(graph.edges)[:, 0]], list(strong_labels))
        return graph.edge_subgraph(keep)

    PatchPredictor.connect = connect
    STATE["rule"], STATE["offset"], STATE["low"] = args.rule, args.offset, args.low
    for t in [float(v) for v in args.thresholds.split(",")]:
        STATE["threshold"] = t
        row = []
        for s in args.sets:
            if city_layout.is_city_dir(s):
                m = evaluate_city_dir(Path(s), predictor, 0)["metrics"]
            else:
                m = evaluate_set(Path(s), predictor, seed=0, progress=False)["mean"]
            row.append(f"{m['f1@5']:.3f}/{m['apls']:.3f}/{m['tlts']:.3f} P{m.get('p@5', 0):.3f}")
        print(f"{args.rule} off{args.offset:g} t{t:g} low{args.low} " + "  ".join(row), flush=True)


if __name__ == "__main__":
    main()
