"""What fine-tuning on a user's labelled cities is worth, by cross-validation
(``csboundary evaluate-finetune``): the set's cities in K folds; for each fold, fine-tune on the
other K-1 and score the held-out cities with the base and the tuned bundle. Every city is scored
once by each, never by a bundle that trained on it; the difference of the means comes with a
paired bootstrap interval over the cities.
"""

from __future__ import annotations

import json
from pathlib import Path

from tqdm import tqdm

from csboundary.data.atomic import atomic_path
from csboundary.errors import InputError
from csboundary.metrics.compare import paired_bootstrap
from csboundary.models.checkpoint import shipped_weights
from csboundary.pipeline.evaluate_set import evaluate_city_dir, score_value, set_cities
from csboundary.pipeline.finetune import FinetuneBudget, finetune
from csboundary.pipeline.patch import load_predictor

COMPARED = ("precision@5", "recall@5", "f1@5", "apls", "tlts")


def folds_of(cities: list[Path], k: int) -> list[list[Path]]:
    """``cities`` dealt into ``k`` folds in their listed order (city i in fold i mod k)."""
    if not 2 <= k <= len(cities):
        raise ValueError(f"folds must be from 2 to the number of cities ({len(cities)})")
    return [cities[i::k] for i in range(k)]


def _scores(cities: list[Path], weights: Path, device: str, engine: str, seed: int, desc: str, progress: bool) -> dict[str, dict]:
    model = load_predictor(weights, device, engine=engine)
    return {c.name: evaluate_city_dir(c, model, seed)["metrics"] for c in tqdm(cities, desc=desc, unit="city", disable=not progress)}


def evaluate_finetune(set_dir: Path, out: Path, *, folds: int = 2, weights: Path | None = None, budget: FinetuneBudget = FinetuneBudget(),
                      seed: int = 0, cache: Path | None = None, device: str = "auto", engine: str = "auto", progress: bool = True) -> dict:
    """Cross-validated scores of fine-tuning ``weights`` on the set ``set_dir``; each fold's run,
    bundle and scores live in ``out/fold-<i>/`` (a stopped evaluation continues), the summary
    in ``out/evaluate-finetune.json``."""
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
            done = finetune(train, fold / "weights.pt", weights=base, work=fold / "work", budget=budget, seed=seed, cache=cache,
                            device=device, progress=progress)
            record = {"fold": i, "train": [c.name for c in train], "held_out": [c.name for c in held_out], "seconds": done["seconds"],
                      "base": _scores(held_out, base, device, engine, seed, f"fold {i}: base", progress),
                      "finetuned": _scores(held_out, fold / "weights.pt", device, engine, seed, f"fold {i}: fine-tuned", progress)}
            with atomic_path(scores_file) as tmp:
                tmp.write_text(json.dumps(record, indent=1) + "\n")
        fold_records.append(record)
        for name in record["held_out"]:
            per_city[name] = {"fold": i, "base": record["base"][name], "finetuned": record["finetuned"][name]}
    summary = {}
    for metric in COMPARED:
        a = [score_value(per_city[n]["base"].get(metric)) for n in per_city]
        b = [score_value(per_city[n]["finetuned"].get(metric)) for n in per_city]
        diff, low, high, wins = paired_bootstrap(a, b, seed=seed)
        summary[metric] = {"base": sum(a) / len(a), "finetuned": sum(b) / len(b), "difference": diff, "interval_95": [low, high],
                           "finetuned_wins": wins}
    result = {"set": str(set_dir), "folds": folds, "base_weights": str(base), "budget": budget.to_dict(), "seed": seed,
              "fold_seconds": [r["seconds"] for r in fold_records], "summary": summary, "per_city": per_city}
    with atomic_path(out / "evaluate-finetune.json") as tmp:
        tmp.write_text(json.dumps(result, indent=1) + "\n")
    return result


def format_finetune(result: dict) -> str:
    """Base against fine-tuned on the held-out cities, per metric, with the interval of the gain."""
    n = len(result["per_city"])
    lines = [f"{n} held-out cities in {result['folds']} folds; fine-tuning took "
             + ", ".join(f"{(s['fpn'] + s['afanet']) / 60:.1f} min" for s in result["fold_seconds"]),
             f"{'':12s}{'base':>8s}{'tuned':>8s}{'gain':>8s}   95 % interval"]
    for metric, s in result["summary"].items():
        low, high = s["interval_95"]
        lines.append(f"{metric:12s}{s['base']:8.3f}{s['finetuned']:8.3f}{s['difference']:+8.3f}   [{low:+.3f}, {high:+.3f}]")
    return "\n".join(lines)
