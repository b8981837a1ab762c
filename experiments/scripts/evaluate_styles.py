"""Score weights bundles on one test city per style (city scale), for the tables of docs/styles.md.

    python experiments/scripts/evaluate_styles.py --bundle all=runs/bundles/worlds.pt \
        --bundle without-suburb=runs/bundles/loso-suburb.pt --out runs/eval/styles.json

Each test city is ``data/cities/test-<style>-s<seed>-2x2-2000`` (``csboundary synth --style STYLE
--split test --seed SEED --tiles 2x2 --tile-size 2000``; classic is ``test-s<seed>-2x2-2000``),
built here if missing; ``--seeds 7,8,9`` scores three cities per style and reports their mean
(one city moves a style's APLS by tenths). Results already in ``--out`` are kept, so an
interrupted run continues. Prints a markdown table of F1@5 / APLS / TLTS per (bundle, style).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

STYLES = ("classic", "grid", "downtown", "suburb", "rural", "irregular", "residential", "leafy", "highway")


def city_dir(style: str, cache: Path, seed: int = 7) -> Path:
    name = f"test-s{seed}-2x2-2000" if style == "classic" else f"test-{style}-s{seed}-2x2-2000"
    path = cache / name
    if not (path / "city.json").exists():
        cli(
            "synth",
            str(path),
            "--style",
            style,
            "--split",
            "test",
            "--seed",
            str(seed),
            "--tiles",
            "2x2",
            "--tile-size",
            "2000",
            "--quiet",
        )
    return path


def cell(style: str, seed: int) -> str:
    """Key of a (style, seed) result; seed 7 keeps the bare style name of earlier result files."""
    return style if seed == 7 else f"{style}-s{seed}"


def mean_row(results: dict, seeds: list[int]) -> dict:
    """Per bundle and style, the mean metrics over ``seeds`` (only where every seed was scored)."""
    out: dict = {}
    for name, row in results.items():
        for style in {k.split("-s")[0] for k in row}:
            cells = [row.get(cell(style, seed)) for seed in seeds]
            if all(cells):
                out.setdefault(name, {})[style] = {
                    k: sum(c[k] for c in cells) / len(cells) for k in ("f1@5", "apls", "tlts")
                }
    return out


def cli(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "csboundary", *args], check=True)


def loso_table(results: dict, held_out: list[str], reference: str = "shipped") -> str:
    """APLS on each held-out style: by the model trained without it, by the other leave-one-out
    models (same budget, the style seen: their mean), and by ``reference`` (the shipped model)."""
    rows = [
        "| style left out | APLS without it (F1@5) | APLS of the same-budget models that saw it (mean of 3) | APLS, shipped model "
        "(longer, saw it) |",
        "|---|---|---|---|",
    ]
    for style in held_out:
        own = results[f"without-{style}"].get(style)
        seen = [
            results[f"without-{o}"][style]["apls"] for o in held_out if o != style and style in results[f"without-{o}"]
        ]
        ref = results.get(reference, {}).get(style)
        rows.append(
            f"| {style} | {own['apls']:.3f} ({own['f1@5']:.3f}) | "
            + (f"{sum(seen) / len(seen):.3f} ({', '.join(f'{v:.3f}' for v in seen)})" if seen else "")
            + " | "
            + (f"{ref['apls']:.3f}" if ref else "")
            + " |"
        )
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bundle", action="append", required=True, help="NAME=PATH of a weights bundle (repeatable)")
    parser.add_argument("--styles", default=",".join(STYLES), help="comma-separated styles to score")
    parser.add_argument(
        "--seeds", default="7", help="comma-separated city seeds per style (the tables show their mean)"
    )
    parser.add_argument("--cache", type=Path, default=Path("data/cities"))
    parser.add_argument("--out", type=Path, required=True, help="JSON of results (read first: finished cells are kept)")
    parser.add_argument(
        "--loso-table",
        action="store_true",
        help="also print the leave-one-style-out table from the 'without-STYLE' rows",
    )
    args = parser.parse_args()
    results = json.loads(args.out.read_text()) if args.out.exists() else {}
    styles, seeds = args.styles.split(","), [int(s) for s in args.seeds.split(",")]
    for item in args.bundle:
        name, path = item.split("=", 1)
        for style in styles:
            for seed in seeds:
                if cell(style, seed) in results.get(name, {}):
                    continue
                with tempfile.TemporaryDirectory() as tmp:
                    report = Path(tmp) / "eval.json"
                    cli(
                        "evaluate-model",
                        str(city_dir(style, args.cache, seed)),
                        "--weights",
                        path,
                        "--json",
                        str(report),
                        "--quiet",
                    )
                    metrics = json.loads(report.read_text())["city"]["metrics"]
                results.setdefault(name, {})[cell(style, seed)] = {
                    k: round(metrics[k], 4) for k in ("f1@5", "apls", "tlts")
                }
                args.out.parent.mkdir(parents=True, exist_ok=True)
                args.out.write_text(json.dumps(results, indent=2) + "\n")
    results = mean_row(results, seeds)
    if args.loso_table:
        print(loso_table(results, [s for s in styles if f"without-{s}" in results]))
    print("| model | " + " | ".join(styles) + " |")
    print("|---|" + "---|" * len(styles))
    for name, row in results.items():
        cells = [
            f"{row[s]['f1@5']:.3f} / {row[s]['apls']:.3f} / {row[s]['tlts']:.3f}" if s in row else "" for s in styles
        ]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
