"""The simulated review of predictions on labelled sets, summed per set: full-map scores, the
review draft and the minutes against drawing from scratch (issue 64's table).

    python experiments/scripts/review_sets.py NAME=PRED:GT[:RASTER] ... [--json OUT.json]

PRED is a prediction folder (its graph.json) and GT its ground truth (a city folder or a vector
file); or PRED a folder of prediction folders and GT a folder of city folders of the same names
(a set: the Ottawa crops). RASTER gives the frame where GT is a vector file in world coordinates.
Per set: mean F1@2 / F1@5 / APLS over its cities; boundaries and review-draft boundaries per km
of true boundary; minutes per km from scratch and to correct the draft (least sure first and at
random), their ratio, and the ratio to reach F1@5 0.95; how well the boundaries' confidence is
calibrated (per class, the length-weighted true share); the per-city scores for paired
comparisons in the JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from csboundary.graph.boundaries import graph_boundaries
from csboundary.graph.polyline import points_along
from csboundary.metrics import apls, pixel_scores
from csboundary.metrics.io import frame_metres_per_px, load_pair
from csboundary.metrics.review_time import boundary_samples, review_report

BINS = (0.0, 0.3, 0.5, 0.7, 0.85, 1.0001)  # boundary confidence classes of the calibration table


def boundary_truth(pred, gt) -> list[tuple[float, float, float]]:
    """(confidence, length px, share of length within 5 px of the truth) of every boundary."""
    samples = boundary_samples(gt)
    near = cKDTree(np.concatenate(samples)) if samples else None
    out = []
    for b in graph_boundaries(pred):
        pts = points_along(b.polyline, 1.0)[0]
        on = near.query(pts, k=1, distance_upper_bound=5.0)[0] < 5.0 if near is not None else np.zeros(len(pts), bool)
        out.append((b.confidence, b.length_px, float(on.mean())))
    return out


def calibration(rows: list[tuple[float, float, float]]) -> list[dict]:
    """Per confidence class: boundaries, their length-weighted mean confidence and true share."""
    table = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        picked = [(c, w, t) for c, w, t in rows if lo <= c < hi]
        if picked:
            c, w, t = (np.array(x) for x in zip(*picked))
            table.append(
                {
                    "from": lo,
                    "to": min(hi, 1.0),
                    "boundaries": len(picked),
                    "mean_confidence": float(np.dot(c, w) / w.sum()),
                    "true_share": float(np.dot(t, w) / w.sum()),
                }
            )
    return table


def pairs(spec: str) -> tuple[str, list[tuple[str, Path, Path, Path | None]]]:
    name, rest = spec.split("=", 1)
    parts = rest.split(":")
    pred, gt, raster = Path(parts[0]), Path(parts[1]), Path(parts[2]) if len(parts) > 2 else None
    if (pred / "graph.json").exists():
        return name, [(name, pred / "graph.json", gt, raster)]
    return name, [(p.parent.name, p, gt / p.parent.name, raster) for p in sorted(pred.glob("*/graph.json"))]


def score_set(items) -> dict:
    cities, totals, truth = {}, {}, []
    for city, pred_path, gt_path, raster in items:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            pred, gt, frame = load_pair(pred_path, gt_path, raster=raster)
        ps = pixel_scores(pred, gt)
        truth += boundary_truth(pred, gt)
        review = review_report(pred, gt, frame_metres_per_px(frame))
        cities[city] = {"f1@2": ps[2.0][2], "f1@5": ps[5.0][2], "apls": apls(pred, gt), "review": review}
        for key in ("scratch_minutes", "true_boundary_km", "boundaries", "draft_boundaries"):
            totals[key] = totals.get(key, 0.0) + review[key]
        for order, o in review["orders"].items():
            for key in ("minutes", "minutes_to_target_f1", "start_f1"):
                totals[f"{order}_{key}"] = totals.get(f"{order}_{key}", 0.0) + o[key]
    km, scratch, n = totals["true_boundary_km"], totals["scratch_minutes"], len(cities)
    out = {
        "cities": n,
        "f1@2": float(np.mean([c["f1@2"] for c in cities.values()])),
        "f1@5": float(np.mean([c["f1@5"] for c in cities.values()])),
        "apls": float(np.nanmean([c["apls"] for c in cities.values()])),
        "true_boundary_km": km,
        "boundaries_per_km": totals["boundaries"] / km,
        "draft_boundaries_per_km": totals["draft_boundaries"] / km,
        "scratch_min_per_km": scratch / km,
    }
    for order in ("confidence", "random"):
        if f"{order}_minutes" in totals:
            out[f"{order}_min_per_km"] = totals[f"{order}_minutes"] / km
            out[f"{order}_ratio"] = totals[f"{order}_minutes"] / scratch
            out[f"{order}_to_target_ratio"] = (
                totals[f"{order}_minutes_to_target_f1"] / scratch
            )  # NaN if a city never reaches it
            out["draft_f1@5"] = totals[f"{order}_start_f1"] / n
    return {"summary": out, "calibration": calibration(truth), "per_city": cities}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sets", nargs="+", help="NAME=PRED:GT[:RASTER]")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    results = {}
    for spec in args.sets:
        name, items = pairs(spec)
        results[name] = score_set(items)
        s = results[name]["summary"]
        print(
            f"{name} ({s['cities']} cities, {s['true_boundary_km']:.2f} km): F1@2 {s['f1@2']:.4f} F1@5 {s['f1@5']:.4f} "
            f"APLS {s['apls']:.4f}; "
            f"{s['boundaries_per_km']:.1f} boundaries/km, {s['draft_boundaries_per_km']:.1f} in the draft (draft F1@5 "
            f"{s['draft_f1@5']:.4f}); from scratch {s['scratch_min_per_km']:.2f} min/km; corrected draft "
            + ", ".join(
                f"{o} {s[o + '_min_per_km']:.2f} min/km = {s[o + '_ratio']:.2f}x (to F1@5 0.95: "
                f"{s[o + '_to_target_ratio']:.2f}x)"
                for o in ("confidence", "random")
                if o + "_ratio" in s
            ),
            flush=True,
        )
        print(
            "  boundary confidence -> true share by length: "
            + "; ".join(
                f"[{row['from']:g}, {row['to']:g}): {row['boundaries']} boundaries, mean {row['mean_confidence']:.2f}, "
                f"true {row['true_share']:.2f}"
                for row in results[name]["calibration"]
            ),
            flush=True,
        )
    if args.json:
        args.json.write_text(
            json.dumps(results, indent=1, default=lambda v: None if isinstance(v, float) and math.isnan(v) else v)
            + "\n"
        )


if __name__ == "__main__":
    main()
