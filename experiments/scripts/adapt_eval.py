"""Experiment: what ``csboundary adapt`` is worth on labelled real sets whose labels it never sees
(docs/adapt.md). Scores are city scale per city, as ``evaluate-set`` computes them.

    .venv/bin/python experiments/scripts/adapt_eval.py SET --out DIR --mode folds|transductive [--folds 2]
        [--cache data/cities] [--fpn-steps N] [--afanet-steps N] [--no-mix] [--no-surface-anchor] [--method JSON]

``folds``: the set's cities dealt into K folds (as ``evaluate-finetune`` deals them); each fold is
scored by a bundle adapted on the images of the other folds. ``transductive``: one bundle
adapted on every image of the set scores every city. Each city is scored by the base and the
adapted bundle; printed: the means of F1@5, precision@5, APLS and TLTS, the 95 % paired-bootstrap
interval of each gain, and the edge confidence's AUC (edges pooled over the set; its interval
from resampling cities). Every bundle, run and score stays in DIR (a stopped run continues).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.metrics.compare import paired_bootstrap
from csboundary.metrics.confidence_quality import TRUE_SHARE, edge_truth, roc_auc
from csboundary.models.checkpoint import shipped_weights
from csboundary.models.training.self_training import AdaptConfig
from csboundary.pipeline.evaluation.finetune_cv import folds_of
from csboundary.pipeline.prediction.city_scores import evaluate_run, predicted_city, score_value, set_cities
from csboundary.pipeline.prediction.patch import load_predictor
from csboundary.pipeline.training.adapt import AdaptBudget, adapt

COMPARED = ("f1@5", "precision@5", "recall@5", "apls", "tlts")


def city_scores(cities: list[Path], weights: Path, seed: int) -> dict:
    """Per city: the city-scale metrics, and each predicted edge's confidence and whether it is true."""
    model = load_predictor(weights, "cpu")
    out = {}
    for city in cities:
        result, lines = predicted_city(city, model, assume_model_gsd=True)
        metrics = evaluate_run(result, lines, seed, scales=("city",))["city"]["metrics"]
        gt = BoundaryGraph.from_world_lines(list(lines), result.grid.transform)
        truth = edge_truth(result.graph, gt) if result.graph.n_edges else np.zeros(0)
        scores = result.graph.edge_scores if result.graph.edge_scores is not None else np.zeros(0)
        out[city.name] = {
            "metrics": {k: score_value(metrics.get(k)) for k in COMPARED},
            "confidence": [float(v) for v in scores],
            "true": [bool(v >= TRUE_SHARE) for v in truth],
        }
    return out


def pooled_auc(per_city: dict, names: list[str]) -> float:
    conf = np.concatenate([np.asarray(per_city[n]["confidence"], float) for n in names] or [np.zeros(0)])
    true = np.concatenate([np.asarray(per_city[n]["true"], bool) for n in names] or [np.zeros(0, bool)])
    return roc_auc(conf, true) if len(conf) else float("nan")


def auc_interval(base: dict, adapted: dict, names: list[str], seed: int, samples: int = 2000) -> dict:
    """Pooled AUC of both, and the 95 % interval of each and of the difference, cities resampled."""
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(samples):
        pick = [names[i] for i in rng.integers(0, len(names), len(names))]
        draws.append((pooled_auc(base, pick), pooled_auc(adapted, pick)))
    draws = np.array(draws)
    ok = np.isfinite(draws).all(axis=1)
    d = draws[ok]
    return {
        "base": pooled_auc(base, names),
        "adapted": pooled_auc(adapted, names),
        "base_interval": np.percentile(d[:, 0], [2.5, 97.5]).tolist(),
        "adapted_interval": np.percentile(d[:, 1], [2.5, 97.5]).tolist(),
        "difference_interval": np.percentile(d[:, 1] - d[:, 0], [2.5, 97.5]).tolist(),
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("set", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--mode", choices=("folds", "transductive"), required=True)
    parser.add_argument("--folds", type=int, default=2)
    parser.add_argument("--weights", type=Path, default=None)
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument("--fpn-steps", type=int, default=None)
    parser.add_argument("--afanet-steps", type=int, default=None)
    parser.add_argument("--method", default="{}", help="AdaptConfig overrides as JSON")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    budget = AdaptBudget.from_dict(
        {k: v for k, v in (("fpn_steps", args.fpn_steps), ("afanet_steps", args.afanet_steps)) if v is not None}
    )
    method = AdaptConfig.from_dict(json.loads(args.method))
    base = args.weights or shipped_weights()
    cities = set_cities(args.set)
    plan = (
        [
            (f"fold-{i}", [c for c in cities if c not in held], held)
            for i, held in enumerate(folds_of(cities, args.folds))
        ]
        if args.mode == "folds"
        else [("all", cities, cities)]
    )
    base_scores, adapted_scores, seconds = {}, {}, []
    for name, train, held in plan:
        folder = args.out / name
        scores_file = folder / "scores.json"
        if not scores_file.exists():
            done = adapt(
                train,
                folder / "adapted.pt",
                weights=base,
                work=folder / "work",
                budget=budget,
                method=method,
                seed=args.seed,
                cache=args.cache,
                device="cpu",
            )
            record = {
                "train": [c.name for c in train],
                "held_out": [c.name for c in held],
                "seconds": done["seconds"],
                "base": city_scores(held, base, args.seed),
                "adapted": city_scores(held, folder / "adapted.pt", args.seed),
            }
            scores_file.write_text(json.dumps(record) + "\n")
        record = json.loads(scores_file.read_text())
        base_scores.update(record["base"])
        adapted_scores.update(record["adapted"])
        seconds.append(sum(record["seconds"].values()))
    names = sorted(base_scores)
    lines = [
        f"{args.set}: {len(names)} cities, mode {args.mode}, budget {budget.to_dict()}, method {method.to_dict()}",
        "adapting took " + ", ".join(f"{s / 60:.1f} min" for s in seconds),
        f"{'':12s}{'base':>8s}{'adapted':>8s}{'gain':>8s}   95 % interval   adapted better in",
    ]
    summary = {}
    for metric in COMPARED:
        a = [base_scores[n]["metrics"][metric] for n in names]
        b = [adapted_scores[n]["metrics"][metric] for n in names]
        diff, low, high, wins = paired_bootstrap(a, b, seed=args.seed)
        summary[metric] = {
            "base": float(np.mean(a)),
            "adapted": float(np.mean(b)),
            "gain": diff,
            "interval_95": [low, high],
        }
        lines.append(
            f"{metric:12s}{np.mean(a):8.3f}{np.mean(b):8.3f}{diff:+8.3f}   [{low:+.3f}, {high:+.3f}]   {wins:.2f} of draws"
        )
    auc = auc_interval(base_scores, adapted_scores, names, args.seed)
    summary["edge_confidence_auc"] = auc
    lines.append(
        f"edge AUC    {auc['base']:8.3f}{auc['adapted']:8.3f}{auc['adapted'] - auc['base']:+8.3f}   "
        f"[{auc['difference_interval'][0]:+.3f}, {auc['difference_interval'][1]:+.3f}]   base interval "
        f"[{auc['base_interval'][0]:.3f}, {auc['base_interval'][1]:.3f}]"
    )
    text = "\n".join(lines)
    print(text)
    (args.out / "report.txt").write_text(text + "\n")
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
