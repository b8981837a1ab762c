"""Scores as people read them: one result as a table, several side by side (the shape of the
paper's tables), and as JSON with undefined metrics (NaN) written as null."""

from __future__ import annotations

import json
import math
from pathlib import Path


def write_scores(path: Path, result: dict) -> None:
    """Scores as JSON, atomically; undefined metrics (NaN) become null."""
    from csboundary.data.atomic import atomic_path
    from csboundary.metrics.aggregate import nan_to_none

    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(nan_to_none(result), indent=1, default=float) + "\n")


def _num(value: float, digits: int = 4) -> str:
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}"


def format_table(result: dict) -> str:
    """A readable summary of :func:`csboundary.metrics.evaluate`'s result."""
    m, c = result["metrics"], result["counts"]
    taus = result["config"]["taus"]
    head = (
        f"{result['inputs']['pred']} vs {result['inputs']['gt']}: {result['scale']} scale, APLS {result['apls_variant']}, "
        f"seed {result['seed']}"
    )
    if result["scale"] == "patch":
        head += (
            f"\n{c['patches_scored']} of {c['patches']} patches scored ({c['patches_with_gt']} with ground truth); "
            "per-patch means"
        )
    lines = [head, f"{'':12s}" + "".join(f"{'tau=' + format(t, 'g'):>10s}" for t in taus)]
    for label, key in (("precision", "precision"), ("recall", "recall"), ("F1", "f1")):
        lines.append(f"{label:12s}" + "".join(f"{_num(m[f'{key}@{t:g}']):>10s}" for t in taus))
    apls_line = f"{'APLS':12s}{_num(m['apls']):>10s}   {result['apls_variant']}"
    if result["apls_variant"] == "symmetric":
        apls_line += f": gt->pred {_num(m['apls_gt_to_pred'])}, pred->gt {_num(m['apls_pred_to_gt'])}"
    lines.append(apls_line)
    lines.append(
        f"{'TLTS':12s}{_num(m['tlts']):>10s}   too long {_num(m['tlts_too_long'])}, too short {_num(m['tlts_too_short'])}, "
        f"infeasible {_num(m['tlts_infeasible'])}"
    )
    lines.append(
        f"{c['pairs']} sampled pairs (phi {result['config']['phi']:g}, snap < {result['config']['snap_radius']:g} px)"
    )
    if "confidence" in result:
        lines.append(format_confidence(result["confidence"]))
    if "review_effort" in result:
        lines.append(format_review(result["review_effort"]))
    return "\n".join(lines)


def format_review(report: dict) -> str:
    """:func:`csboundary.metrics.review_time.review_report` in a few lines, per km where known."""
    km = report.get("true_boundary_km")
    scale, unit = (1 / km, "min/km") if km else (1.0, "min")
    target = report["costs"]["target_f1"]
    held = report["held_back_boundaries"]
    lines = [
        f"review effort ({report['boundaries']} boundaries, {report['draft_boundaries']} in the review draft"
        + (f", {held} held back" if held else "")
        + f"; {report['false_boundaries']} false, {report['cut_pieces']} pieces cut out; "
        + (f"{km:.3f} km of true boundary" if km else f"{report['true_boundary_px']:.0f} px of true boundary")
        + "):",
        f"  from scratch {_num(report['scratch_minutes'] * scale, 1)} {unit} ({report['scratch_clicks']} clicks)",
    ]
    for name, o in report["orders"].items():
        ratio = o["minutes"] / report["scratch_minutes"] if report["scratch_minutes"] else float("nan")
        lines.append(
            f"  {name + ' order':17s} corrected map {_num(o['minutes'] * scale, 1)} {unit} = {_num(ratio, 2)}x scratch (look "
            f"{_num(o['look_minutes'] * scale, 1)}, "
            f"draw {_num(o['draw_minutes'] * scale, 1)}); F1@5 {_num(o['start_f1'], 3)} -> {_num(o['end_f1'], 3)}; "
            f"to F1@5 {target:g}: {_num(o['minutes_to_target_f1'] * scale, 1)} {unit}"
        )
    if "note" in report:
        lines.append(f"  ({report['note']})")
    if report.get("metres_per_px_assumed"):
        lines.append(
            f"  (lengths priced at an assumed {report['metres_per_px']:g} m per pixel: the frame has no ground size)"
        )
    return "\n".join(lines)


def format_confidence(report: dict) -> str:
    """:func:`csboundary.metrics.confidence_quality.confidence_report` in two lines."""
    review = ", ".join(
        f"{float(share):.0%} -> {_num(r['false_length'], 2)} of false length ({_num(r['false_edges'], 2)} of false edges; "
        f"of what any order could show: {_num(r.get('false_length_of_attainable'), 2)} by length, "
        f"{_num(r.get('false_edges_of_attainable'), 2)} by edges)"
        for share, r in report["review"].items()
    )
    return (
        f"confidence: {report['edges']} edges ({_num(report['share_true'], 2)} true), AUC {_num(report['auc'], 3)}, "
        f"ECE {_num(report['ece'], 3)}\nreviewing the least sure {review}"
    )


def format_rows(results: dict[str, dict]) -> str:
    """Several results side by side, one row each (the shape of the paper's tables)."""
    first = next(iter(results.values()))
    taus = [f"{t:g}" for t in first["config"]["taus"]]
    columns = [f"{k}@{t}" for k in ("precision", "recall", "f1") for t in taus] + ["apls", "tlts"]
    header = ["P@" + t for t in taus] + ["R@" + t for t in taus] + ["F1@" + t for t in taus] + ["APLS", "TLTS"]
    width = max(12, *(len(k) + 2 for k in results))
    lines = [f"{'':{width}s}" + "".join(f"{h:>8s}" for h in header)]
    for label, result in results.items():
        m = result["metrics"]
        lines.append(f"{label:{width}s}" + "".join(f"{_num(m[c], 3):>8s}" for c in columns))
    return "\n".join(lines)
