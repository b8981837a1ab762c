"""Validation curves from a training log (JSON lines) as a small dependency-free SVG.

Usage: python -m csboundary.viz.curves runs/fpn/train.log docs/fpn-validation.svg val_loss val_seg_f1
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b")


def read_validations(log: str | Path) -> list[dict]:
    rows = []
    for line in Path(log).read_text().splitlines():
        record = json.loads(line)
        if record.get("event") == "validate":
            rows.append(record)
    return rows


def curves_svg(rows: list[dict], keys: list[str], title: str, width: int = 640, height: int = 360) -> str:
    """One panel, x = step, each key scaled to its own [min, max] range (labelled in the legend)."""
    left, right, top, bottom = 50, 190, 30, 40
    steps = [r["step"] for r in rows]
    x0, x1 = min(steps), max(steps) if len(steps) > 1 else min(steps) + 1
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" font-size="12">',
        f'<rect width="{width}" height="{height}" fill="white"/>',
        f'<text x="{left}" y="18" font-size="14">{title}</text>',
        f'<line x1="{left}" y1="{height - bottom}" x2="{width - right}" y2="{height - bottom}" stroke="black"/>',
        f'<line x1="{left}" y1="{top}" x2="{left}" y2="{height - bottom}" stroke="black"/>',
        f'<text x="{left}" y="{height - 12}">step {x0}</text>',
        f'<text x="{width - right - 60}" y="{height - 12}">step {x1}</text>',
    ]
    for k, key in enumerate(keys):
        values = [(r["step"], r[key]) for r in rows if isinstance(r.get(key), (int, float)) and r[key] == r[key]]
        if not values:
            continue
        lo, hi = min(v for _, v in values), max(v for _, v in values)
        span = hi - lo or 1.0
        pts = " ".join(
            f"{left + (s - x0) / (x1 - x0) * (width - left - right):.1f},"
            f"{top + (1 - (v - lo) / span) * (height - top - bottom):.1f}"
            for s, v in values
        )
        colour = COLOURS[k % len(COLOURS)]
        parts.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
        parts.append(
            f'<text x="{width - right + 10}" y="{top + 18 * k + 10}" fill="{colour}">{key}: {values[0][1]:.3g} -&gt; '
            f"{values[-1][1]:.3g}</text>"
        )
    parts.append(
        f'<text x="{width - right + 10}" y="{top + 18 * len(keys) + 16}" fill="gray">(each curve on its own scale)</text>'
    )
    parts.append("</svg>")
    return "\n".join(parts)


def main(argv: list[str]) -> None:
    log, out, *keys = argv
    rows = read_validations(log)
    Path(out).write_text(curves_svg(rows, keys, f"validation: {Path(log).parent.name}"))


if __name__ == "__main__":
    main(sys.argv[1:])
