"""Scores of a model on a set of small labelled cities (e.g. real crops imported from masks).

A validation set is a folder of city directories, listed in ``set.json`` by ``import-masks`` (or
every city directory in the folder). Each city is predicted as ``predict`` does and scored against
its ground truth at city scale; the set's score is the plain mean over cities of every metric
(each crop counts once, and a crop with an empty prediction counts as 0, not skipped).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from tqdm import tqdm

from csboundary.models.patch_model import PatchModel
from csboundary.pipeline.prediction.city_scores import evaluate_city_dir, score_value, set_cities

HEADLINE = ("precision@5", "recall@5", "f1@2", "f1@5", "f1@10", "apls", "tlts")


def evaluate_set(set_dir: str | Path, model: PatchModel, seed: int = 0, progress: bool = True) -> dict[str, Any]:
    """Per-city and mean scores of ``model`` on every city of a set."""
    cities = set_cities(set_dir)
    per_city = {}
    for city_dir in tqdm(cities, desc="evaluate set", unit="city", disable=not progress):
        per_city[city_dir.name] = evaluate_city_dir(city_dir, model, seed)
    keys = per_city[cities[0].name]["metrics"].keys()
    mean = {k: _mean([s["metrics"][k] for s in per_city.values()]) for k in keys}
    out = {"set": str(set_dir), "cities": len(cities), "mean": mean, "per_city": per_city}
    reviews = [s["review_effort"] for s in per_city.values() if "review_effort" in s]
    if reviews:
        out["review_effort"] = set_review_effort(reviews)
    return out


def set_review_effort(reviews: list[dict]) -> dict[str, float]:
    """The set's simulated review per km of true boundary: every city's minutes summed over all
    their km (a long city weighs more than a short one), and as a ratio to drawing from scratch.
    Minutes to the target F1 count only the cities that reach it (``cities_reaching_target``); an
    order is reported when every city has it (a prediction without confidence has only random)."""
    km = sum(r["true_boundary_km"] or 0.0 for r in reviews)
    scratch = sum(r["scratch_minutes"] for r in reviews)
    out = {"true_boundary_km": km, "cities": len(reviews), "scratch_min_per_km": scratch / km if km else math.nan}
    for order in [o for o in reviews[0]["orders"] if all(o in r["orders"] for r in reviews)]:
        minutes = sum(r["orders"][order]["minutes"] for r in reviews)
        out[f"{order}_min_per_km"] = minutes / km if km else math.nan
        out[f"{order}_ratio_to_scratch"] = minutes / scratch if scratch else math.nan
        hit = [r for r in reviews if math.isfinite(r["orders"][order]["minutes_to_target_f1"])]
        hit_km = sum(r["true_boundary_km"] or 0.0 for r in hit)
        out[f"{order}_to_target_min_per_km"] = (
            sum(r["orders"][order]["minutes_to_target_f1"] for r in hit) / hit_km if hit_km else math.nan
        )
        out[f"{order}_cities_reaching_target"] = len(hit)
    return out


def _mean(values: list[float]) -> float:
    return sum(map(score_value, values)) / len(values)


def format_set(result: dict[str, Any]) -> str:
    """One row per city and the mean, headline metrics only."""
    width = max(10, *(len(n) + 2 for n in result["per_city"]))
    lines = [f"{'':{width}s}" + "".join(f"{h:>13s}" for h in HEADLINE)]
    rows = [(n, s["metrics"]) for n, s in result["per_city"].items()] + [(f"mean ({result['cities']})", result["mean"])]
    for name, m in rows:
        lines.append(f"{name:{width}s}" + "".join(f"{m.get(h, float('nan')):13.3f}" for h in HEADLINE))
    review = result.get("review_effort")
    if review:
        lines.append(
            f"review effort over {review['true_boundary_km']:.2f} km of true boundary: from scratch "
            f"{review['scratch_min_per_km']:.1f} min/km; corrected draft "
            + ", ".join(
                f"{o} order {review[o + '_min_per_km']:.1f} min/km = {review[o + '_ratio_to_scratch']:.2f}x "
                f"(to the target F1@5 {review[o + '_to_target_min_per_km']:.1f} "
                f"min/km, {review[o + '_cities_reaching_target']} of {review['cities']} cities reach it)"
                for o in ("confidence", "random")
                if o + "_min_per_km" in review
            )
        )
    return "\n".join(lines)
