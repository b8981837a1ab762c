"""Experiment: edge confidence models fitted on the fitting cities' evidence, scored on every set
(synthetic test cities by style, the Ottawa crops, the dense-urban NYC patch), beside the raw
edge score they replace. Reads the files experiments/scripts/confidence_evidence.py wrote.

    .venv/bin/python experiments/scripts/confidence_compare.py runs/confidence/evidence [--features all|graph|nomaps...]
    [--trees 200 --depth 3]
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path

import numpy as np

from csboundary.graph.edge_evidence import FEATURES
from csboundary.metrics.confidence_quality import TRUE_SHARE, confidence_report, precision_recall_by_threshold, roc_auc
from csboundary.models.confidence_model import fit_edge_confidence

FEATURE_SETS = {
    "all": FEATURES,
    "no_surface": tuple(f for f in FEATURES if not f.startswith("surface")),
    "no_score": tuple(f for f in FEATURES if f != "score"),
    "maps": (
        "boundary_mean",
        "boundary_min",
        "boundary_p10",
        "keypoint_max",
        "surface_on",
        "surface_high",
        "surface_low",
        "surface_contrast",
    ),
    "maps_shape": (
        "boundary_mean",
        "boundary_min",
        "boundary_p10",
        "keypoint_max",
        "surface_on",
        "surface_high",
        "surface_low",
        "surface_contrast",
        "log_length",
        "sinuosity",
        "log_piece_length",
    ),
}


def load(files: list[str]) -> dict[str, np.ndarray]:
    parts = [dict(np.load(f)) for f in files]
    parts = [p for p in parts if len(p["truth_share"])]
    out = {k: np.concatenate([p[k] for p in parts]) for k in ("evidence", "truth_share", "length")}
    out["group"] = np.concatenate([np.full(len(p["truth_share"]), k) for k, p in enumerate(parts)])
    return out


def row(name: str, p: np.ndarray, data: dict) -> str:
    r = confidence_report(p, data["truth_share"], data["length"])
    rv = r["review"]
    return (
        f"{name:28s} {r['edges']:6d} {r['share_true']:6.2f} {r['auc']:7.3f} {r['ece']:7.3f} "
        f"{rv['0.1']['false_length']:6.2f} {rv['0.2']['false_length']:6.2f} {rv['0.2']['false_edges']:6.2f} "
        f"{rv['0.5']['false_length']:6.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("folder", type=Path)
    parser.add_argument("--features", default="all", help=f"{', '.join(FEATURE_SETS)} or a comma-separated list")
    parser.add_argument("--trees", type=int, default=200)
    parser.add_argument("--depth", type=int, default=2)
    parser.add_argument("--rate", type=float, default=0.05)
    parser.add_argument(
        "--tree-share", type=float, default=0.5, help="share on the ground truth the trees learn (calibration: 0.5)"
    )
    parser.add_argument(
        "--bundle", type=Path, default=None, help="score this bundle's confidence instead of fitting one"
    )
    parser.add_argument("--brief", action="store_true", help="pooled sets only")
    parser.add_argument(
        "--curves",
        action="store_true",
        help="also the pooled sets' precision and kept true length against --min-confidence",
    )
    parser.add_argument(
        "--bootstrap",
        type=int,
        default=0,
        help="95 %% intervals of the real sets' AUC and ECE from this many resamples of cities (edges for one city)",
    )
    parser.add_argument("--single", action="store_true", help="also each feature's own AUC on the real sets")
    args = parser.parse_args()
    d = str(args.folder)
    fit = load(sorted(glob.glob(f"{d}/fit-*.npz")))
    features = FEATURE_SETS.get(args.features) or tuple(args.features.split(","))
    if args.bundle:
        from csboundary.models.checkpoint import load_checkpoint
        from csboundary.models.confidence_model import EdgeConfidence

        model = EdgeConfidence.from_dict(load_checkpoint(args.bundle, ("bundle",))["confidence"], args.bundle)
        args.features, args.trees = f"{args.bundle}'s", model.n_trees
    else:
        model = fit_edge_confidence(
            fit["evidence"],
            fit["truth_share"] >= TRUE_SHARE,
            fit["group"],
            features,
            n_trees=args.trees,
            depth=args.depth,
            learning_rate=args.rate,
            tree_positive=fit["truth_share"] >= args.tree_share,
        )
    sets = {"fit (in sample)": sorted(glob.glob(f"{d}/fit-*.npz"))}
    for f in sorted(glob.glob(f"{d}/test-*.npz")):
        sets[Path(f).stem] = [f]
    sets["synthetic test (pooled)"] = sorted(glob.glob(f"{d}/test-*.npz"))
    sets["ottawa (14 crops)"] = sorted(glob.glob(f"{d}/ottawa-*.npz"))
    sets["nyc dense-urban"] = sorted(glob.glob(f"{d}/nyc-*.npz"))
    print(
        f"features {args.features}, {args.trees} trees of depth {args.depth}, rate {args.rate}; "
        f"fitted on {len(fit['length'])} edges"
    )
    print(
        f"{'set / confidence':28s} {'edges':>6s} {'true':>6s} {'AUC':>7s} {'ECE':>7s} {'fl@10':>6s} {'fl@20':>6s} {'fe@20':>6s} "
        f"{'fl@50':>6s}"
    )
    for name, files in sets.items():
        if not files or (args.brief and not name.startswith(("ottawa", "nyc", "synthetic"))):
            continue
        data = load(files)
        print(row(name + " raw", data["evidence"][:, FEATURES.index("score")], data))
        print(row(name + " model", model.probability(data["evidence"]), data))
        if args.curves and name.startswith(("ottawa", "nyc", "synthetic")):
            rows = precision_recall_by_threshold(
                model.probability(data["evidence"]), data["truth_share"], data["length"]
            )
            print("   P       " + " ".join(f"{r['min_confidence']:5.1f}" for r in rows))
            print("   prec    " + " ".join(f"{r['precision']:5.2f}" for r in rows))
            print("   kept tl " + " ".join(f"{r['true_length_kept']:5.2f}" for r in rows))
        if args.bootstrap and name.startswith(("ottawa", "nyc")):
            rng = np.random.default_rng(0)
            p, groups = model.probability(data["evidence"]), data["group"]
            ids = np.unique(groups)
            stats = []
            for _ in range(args.bootstrap):
                if len(ids) > 1:
                    pick = np.concatenate([np.flatnonzero(groups == g) for g in rng.choice(ids, len(ids))])
                else:
                    pick = rng.integers(0, len(p), len(p))
                r = confidence_report(p[pick], data["truth_share"][pick], data["length"][pick])
                stats.append((r["auc"], r["ece"]))
            lo, hi = np.nanpercentile(np.array(stats), [2.5, 97.5], axis=0)
            print(f"   95 % interval: AUC [{lo[0]:.3f}, {hi[0]:.3f}], ECE [{lo[1]:.3f}, {hi[1]:.3f}]")
        if args.single and name.startswith(("ottawa", "nyc", "synthetic")):
            positive = data["truth_share"] >= TRUE_SHARE
            print(
                "   "
                + ", ".join(f"{f} {roc_auc(data['evidence'][:, i], positive):.2f}" for i, f in enumerate(FEATURES))
            )


if __name__ == "__main__":
    main()
