"""Picture: F1@5 against minutes of simulated review per km, least sure first and in a random order,
with drawing from scratch marked, for cities scored by ``evaluate-set --json`` or
``experiments/scripts/review_sets.py --json`` (docs/metrics.md).

    .venv/bin/python experiments/scripts/review_curves.py OUT.svg SCORES.json:CITY [SCORES.json:CITY ...]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

COLOURS = {"confidence": "#d62728", "random": "#1f77b4"}


def panel(review: dict, title: str, x: int, width: int, height: int) -> list[str]:
    km = review["true_boundary_km"]
    top, bottom, left = 30, 40, 45
    orders = review["orders"]
    x_max = max(max(o["curve"]["minutes"]) for o in orders.values()) / km
    x_max = max(x_max, review["scratch_minutes"] / km) * 1.05

    def px(minutes_per_km: float, f1: float) -> tuple[float, float]:
        return (x + left + (width - left - 15) * minutes_per_km / x_max, top + (height - top - bottom) * (1 - f1))

    out = [f'<text x="{x + left}" y="18" font-weight="bold">{title}</text>']
    x0, y0 = px(0, 0)
    x1, y1 = px(x_max, 1)
    out.append(f'<rect x="{x0}" y="{y1}" width="{x1 - x0}" height="{y0 - y1}" fill="none" stroke="#999"/>')
    for f in (0.0, 0.5, 0.95, 1.0):
        _, y = px(0, f)
        out.append(f'<text x="{x0 - 5}" y="{y + 4}" text-anchor="end">{f:g}</text>')
    _, y95 = px(0, 0.95)
    out.append(f'<line x1="{x0}" y1="{y95}" x2="{x1}" y2="{y95}" stroke="#ccc" stroke-dasharray="3,3"/>')
    xs, _ = px(review["scratch_minutes"] / km, 0)
    out.append(f'<line x1="{xs}" y1="{y1}" x2="{xs}" y2="{y0}" stroke="#2ca02c" stroke-dasharray="5,3"/>')
    out.append(f'<text x="{xs + 3}" y="{y0 - 5}" fill="#2ca02c">from scratch</text>')
    for name, o in orders.items():
        points = " ".join(
            f"{a:.1f},{b:.1f}" for a, b in (px(m / km, f) for m, f in zip(o["curve"]["minutes"], o["curve"]["f1"]))
        )
        out.append(f'<polyline points="{points}" fill="none" stroke="{COLOURS[name]}" stroke-width="2"/>')
    for m in range(0, int(x_max) + 1, max(1, int(x_max) // 5)):
        xt, _ = px(m, 0)
        out.append(f'<text x="{xt}" y="{y0 + 14}" text-anchor="middle">{m}</text>')
    out.append(
        f'<text x="{(x0 + x1) / 2}" y="{height - 8}" text-anchor="middle">minutes per km of true boundary</text>'
    )
    return out


def main(argv: list[str]) -> None:
    out, items = Path(argv[0]), argv[1:]
    width, height = 420, 300
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width * len(items)}" height="{height + 20}" font-family="sans-serif" '
        f'font-size="12"><rect width="100%" height="100%" fill="white"/>'
    ]
    for k, item in enumerate(items):
        path, city = item.rsplit(":", 1)
        scores = json.loads(Path(path).read_text())
        sets = (
            [scores] if "per_city" in scores else list(scores.values())
        )  # evaluate-set's JSON, or review_sets.py's (one per set)
        found = next(s["per_city"][city] for s in sets if city in s["per_city"])
        review = found.get("review_effort") or found["review"]
        parts += panel(review, f"{city}: F1@5 during review", k * width, width, height)
    legend = " ".join(f'<tspan fill="{c}">&#9644; {n} order</tspan>' for n, c in COLOURS.items())
    parts.append(f'<text x="10" y="{height + 14}">{legend} (least sure first = confidence)</text></svg>')
    out.write_text("\n".join(parts) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
