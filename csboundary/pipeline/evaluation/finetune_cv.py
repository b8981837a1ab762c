"""What fine-tuning on a user's labelled cities is worth, by cross-validation
(``csboundary evaluate-finetune``): the set's cities in K folds; for each fold, fine-tune on the
other K-1 and score the held-out cities with the base and the tuned bundle. Every city is scored
once by each, never by a bundle that trained on it; the difference of the means comes with a
paired bootstrap interval over the cities. The mapping loop is priced in a reviewer's minutes
(:func:`mapping_loop`): review a few blocks, fine-tune, correct the re-drafted rest.
"""

from __future__ import annotations

import json
from pathlib import Path

from tqdm import tqdm

from csboundary.data.atomic import atomic_path
from csboundary.data.folder_lock import locked_folder
from csboundary.errors import InputError
from csboundary.metrics.compare import paired_bootstrap
from csboundary.models.checkpoint import load_checkpoint, shipped_weights
from csboundary.pipeline.prediction.city_scores import evaluate_city_dir, score_value, set_cities
from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor
from csboundary.pipeline.training.finetune import FinetuneBudget, finetune

COMPARED = ("precision@5", "recall@5", "f1@5", "apls", "tlts")


def folds_of(cities: list[Path], k: int) -> list[list[Path]]:
    """``cities`` dealt into ``k`` folds in their listed order (city i in fold i mod k)."""
    if not 2 <= k <= len(cities):
        raise ValueError(f"folds must be from 2 to the number of cities ({len(cities)})")
    return [cities[i::k] for i in range(k)]


def _scores(
    cities: list[Path], weights: Path, device: str, engine: str, seed: int, desc: str, progress: bool
) -> dict[str, dict]:
    """Each city's metrics, with the minutes of its simulated review under ``review``."""
    model = load_predictor(weights, device, engine=engine)
    out = {}
    for city in tqdm(cities, desc=desc, unit="city", disable=not progress):
        scores = evaluate_city_dir(city, model, seed)
        out[city.name] = {**scores["metrics"], "review": review_minutes(scores.get("review_effort"))}
    return out


def review_minutes(report: dict | None) -> dict | None:
    """The few numbers of a simulated review the mapping loop needs: minutes to correct the draft
    (least sure first when there is a confidence), from scratch, and the km of true boundary."""
    if not report:
        return None
    order = report["orders"].get("confidence") or report["orders"]["random"]
    return {
        "corrected_minutes": order["minutes"],
        "scratch_minutes": report["scratch_minutes"],
        "km": report["true_boundary_km"],
    }


def mapping_loop(records: list[dict], per_city: dict) -> list[dict]:
    """Per fold, what reviewing a few blocks and fine-tuning buys a person mapping a city: the
    minutes to review the base bundle's drafts of the training cities, to correct the tuned
    bundle's drafts of the held-out cities (and the base bundle's, for comparison), and to draw
    each from scratch. The base bundle's review of a city is fold-independent: it is the one
    scored when that city was held out."""

    def total(names, bundle, key):
        values = [(per_city[n][bundle].get("review") or {}).get(key) for n in names]
        return float(sum(values)) if values and all(v is not None for v in values) else float("nan")

    out = []
    for r in records:
        train, held = r["train"], r["held_out"]
        out.append(
            {
                "fold": r["fold"],
                "train_km": total(train, "base", "km"),
                "held_out_km": total(held, "base", "km"),
                "train_review_minutes": total(train, "base", "corrected_minutes"),
                "train_scratch_minutes": total(train, "base", "scratch_minutes"),
                "held_out_tuned_minutes": total(held, "finetuned", "corrected_minutes"),
                "held_out_base_minutes": total(held, "base", "corrected_minutes"),
                "held_out_scratch_minutes": total(held, "base", "scratch_minutes"),
            }
        )
    return out


def _held_out_confidence(cities: list[Path], tuned: Path, base: Path, device: str, progress: bool) -> dict:
    """Every held-out edge the tuned networks draw: whether it is true, and the confidence the
    tuned bundle gives it (refitted or kept) beside the base bundle's confidence table applied
    to the same edges, so the two tables are compared on identical evidence."""
    import numpy as np

    from csboundary.models.confidence_model import EdgeConfidence
    from csboundary.models.device import resolve_device
    from csboundary.pipeline.training.confidence_fit import city_edges

    predictor = PatchPredictor.load(tuned, resolve_device(device))
    tables = {
        "base": EdgeConfidence.from_dict(load_checkpoint(base, ("bundle",))["confidence"], base),
        "tuned": EdgeConfidence.from_dict(load_checkpoint(tuned, ("bundle",))["confidence"], tuned),
    }
    edges = [
        city_edges(c, predictor, assume_model_gsd=True)
        for c in tqdm(cities, desc="held-out edges", unit="city", disable=not progress)
    ]
    edges = [e for e in edges if e.graph.n_edges]
    evidence = np.concatenate([e.evidence for e in edges]) if edges else np.zeros((0, 1))
    out = {"true": np.concatenate([e.positive for e in edges]).tolist() if edges else []}
    for name, table in tables.items():
        out[name] = table.probability(evidence).tolist() if edges else []
    return out


def confidence_summary(records: list[dict], seed: int = 0, samples: int = 1000) -> dict:
    """AUC and ECE of the base and the tuned confidence over all held-out edges of every fold,
    with 95 % intervals from resampling edges."""
    import numpy as np

    from csboundary.metrics.confidence_quality import expected_calibration_error, roc_auc

    true = np.concatenate([np.asarray(r["true"], bool) for r in records])
    out = {"edges": int(len(true)), "share_true": float(true.mean()) if len(true) else float("nan")}
    rng = np.random.default_rng(seed)
    draws = [rng.integers(0, len(true), len(true)) for _ in range(samples)] if len(true) else []
    for name in ("base", "tuned"):
        p = np.concatenate([np.asarray(r[name], float) for r in records])
        row = {"auc": roc_auc(p, true), "ece": expected_calibration_error(p, true)}
        for key, fn in (("auc", roc_auc), ("ece", expected_calibration_error)):
            values = np.array([fn(p[d], true[d]) for d in draws])
            values = values[np.isfinite(values)]
            row[f"{key}_interval_95"] = (
                np.percentile(values, [2.5, 97.5]).tolist() if len(values) else [float("nan")] * 2
            )
        out[name] = row
    return out


def evaluate_finetune(
    set_dir: Path,
    out: Path,
    *,
    folds: int = 2,
    weights: Path | None = None,
    budget: FinetuneBudget = FinetuneBudget(),
    seed: int = 0,
    cache: Path | None = None,
    device: str = "auto",
    engine: str = "auto",
    progress: bool = True,
) -> dict:
    """Cross-validated scores of fine-tuning ``weights`` on the set ``set_dir``; each fold's run,
    bundle and scores live in ``out/fold-<i>/`` (a stopped evaluation continues), the summary
    in ``out/evaluate-finetune.json``. A second evaluation into ``out`` is refused in one line."""
    with locked_folder(out):
        return _evaluate_finetune(
            set_dir,
            Path(out),
            folds=folds,
            weights=weights,
            budget=budget,
            seed=seed,
            cache=cache,
            device=device,
            engine=engine,
            progress=progress,
        )


def _evaluate_finetune(
    set_dir: Path,
    out: Path,
    *,
    folds: int,
    weights: Path | None,
    budget: FinetuneBudget,
    seed: int,
    cache: Path | None,
    device: str,
    engine: str,
    progress: bool,
) -> dict:
    cities = set_cities(set_dir)
    try:
        split = folds_of(cities, folds)
    except ValueError as exc:
        raise InputError(set_dir, str(exc)) from exc
    base = Path(weights) if weights else shipped_weights()
    cache = Path(cache) if cache else out / "synthetic"
    per_city, fold_records = {}, []
    for i, held_out in enumerate(split):
        fold = out / f"fold-{i}"
        scores_file = fold / "scores.json"
        if scores_file.exists():
            record = json.loads(scores_file.read_text())
        else:
            train = [c for c in cities if c not in held_out]
            done = finetune(
                train,
                fold / "weights.pt",
                weights=base,
                work=fold / "work",
                budget=budget,
                seed=seed,
                cache=cache,
                device=device,
                progress=progress,
            )
            record = {
                "fold": i,
                "train": [c.name for c in train],
                "held_out": [c.name for c in held_out],
                "seconds": done["seconds"],
                "base": _scores(held_out, base, device, engine, seed, f"fold {i}: base", progress),
                "finetuned": _scores(
                    held_out, fold / "weights.pt", device, engine, seed, f"fold {i}: fine-tuned", progress
                ),
                "confidence_refit": done.get("confidence"),
                "confidence": _held_out_confidence(held_out, fold / "weights.pt", base, device, progress),
            }
            with atomic_path(scores_file) as tmp:
                tmp.write_text(json.dumps(record, indent=1) + "\n")
        fold_records.append(record)
        for name in record["held_out"]:
            per_city[name] = {"fold": i, "base": record["base"][name], "finetuned": record["finetuned"][name]}
    summary = {}
    for metric in COMPARED:  # a fold written by an older build holds the metrics alone: they are read the same
        a = [score_value(per_city[n]["base"].get(metric)) for n in per_city]
        b = [score_value(per_city[n]["finetuned"].get(metric)) for n in per_city]
        diff, low, high, wins = paired_bootstrap(a, b, seed=seed)
        summary[metric] = {
            "base": sum(a) / len(a),
            "finetuned": sum(b) / len(b),
            "difference": diff,
            "interval_95": [low, high],
            "finetuned_wins": wins,
        }
    result = {
        "set": str(set_dir),
        "folds": folds,
        "base_weights": str(base),
        "budget": budget.to_dict(),
        "seed": seed,
        "fold_seconds": [r["seconds"] for r in fold_records],
        "summary": summary,
        "per_city": per_city,
        "confidence": confidence_summary([r["confidence"] for r in fold_records], seed),
        "confidence_refit": [r.get("confidence_refit") for r in fold_records],
        "mapping_loop": mapping_loop(fold_records, per_city),
    }
    with atomic_path(out / "evaluate-finetune.json") as tmp:
        tmp.write_text(json.dumps(result, indent=1) + "\n")
    return result


def format_finetune(result: dict) -> str:
    """Base against fine-tuned on the held-out cities, per metric, with the interval of the gain."""
    n = len(result["per_city"])
    lines = [
        f"{n} held-out cities in {result['folds']} folds; fine-tuning took "
        + ", ".join(f"{sum(s.values()) / 60:.1f} min" for s in result["fold_seconds"]),
        f"{'':12s}{'base':>8s}{'tuned':>8s}{'gain':>8s}   95 % interval",
    ]
    for metric, s in result["summary"].items():
        low, high = s["interval_95"]
        lines.append(
            f"{metric:12s}{s['base']:8.3f}{s['finetuned']:8.3f}{s['difference']:+8.3f}   [{low:+.3f}, {high:+.3f}]"
        )
    c = result.get("confidence")
    if c and c["edges"]:
        lines.append(
            f"edge confidence on the {c['edges']} held-out edges of the tuned networks ({c['share_true']:.2f} true):"
        )
        for name, label in (("base", "base bundle's table"), ("tuned", "tuned bundle's")):
            r = c[name]
            lines.append(
                f"  {label:20s} AUC {r['auc']:.3f} [{r['auc_interval_95'][0]:.3f}, {r['auc_interval_95'][1]:.3f}], "
                f"ECE {r['ece']:.3f} [{r['ece_interval_95'][0]:.3f}, {r['ece_interval_95'][1]:.3f}]"
            )
    for i, refit in enumerate(result.get("confidence_refit") or []):
        if refit:
            lines.append(f"  fold {i}: {refit['reason']}")
    loop = [
        f for f in result.get("mapping_loop") or [] if f["train_km"] == f["train_km"]
    ]  # NaN: folds of an older build
    if loop:
        lines.append("the mapping loop in minutes (simulated review; per km of true boundary):")
        for f in loop:
            tk, hk = f["train_km"] or float("nan"), f["held_out_km"] or float("nan")
            lines.append(
                f"  fold {f['fold']}: review the training cities' drafts {f['train_review_minutes']:.1f} min "
                f"({f['train_review_minutes'] / tk:.1f} min/km; from scratch {f['train_scratch_minutes'] / tk:.1f}); "
                f"correct the held-out re-drafts {f['held_out_tuned_minutes']:.1f} min "
                f"({f['held_out_tuned_minutes'] / hk:.1f} min/km; base draft {f['held_out_base_minutes'] / hk:.1f}, "
                f"from scratch {f['held_out_scratch_minutes'] / hk:.1f})"
            )
    return "\n".join(lines)
