"""Paired bootstrap of two ``evaluate-set`` results on the same set: is B's mean score different
from A's, or within what the choice of cities can move it?

    python scripts/compare_sets.py A.json B.json [--metrics f1@5,apls,tlts] [--samples 10000] [--seed 0]

Resamples the set's cities with replacement (the same draw for A and B, since both scored the same
cities) and prints, per metric, A's and B's means, the mean of B - A and its 95 % interval, and
the share of resamples in which B wins. With 14 crops an interval that spans 0 means the set
cannot tell the two apart.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from csboundary.metrics.compare import paired_bootstrap


def per_city(path: str, metric: str) -> dict[str, float]:
    """``metric`` of every city of an evaluate-set JSON (None or NaN counts 0, as in its mean)."""
    result = json.load(open(path))
    out = {}
    for name, scores in result["per_city"].items():
        value = scores["metrics"].get(metric)
        out[name] = 0.0 if value is None or value != value else float(value)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a")
    parser.add_argument("b")
    parser.add_argument("--metrics", default="f1@5,apls,tlts")
    parser.add_argument("--samples", type=int, default=10000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"A = {args.a}\nB = {args.b}")
    for metric in args.metrics.split(","):
        a, b = per_city(args.a, metric), per_city(args.b, metric)
        if a.keys() != b.keys():
            raise SystemExit(f"error: the two results scored different cities ({sorted(a.keys() ^ b.keys())[:5]} ...)")
        names = sorted(a)
        va, vb = np.array([a[n] for n in names]), np.array([b[n] for n in names])
        mean, low, high, wins = paired_bootstrap(va, vb, args.samples, args.seed)
        print(
            f"{metric:6s} A {va.mean():.3f}  B {vb.mean():.3f}  B-A {mean:+.3f} [{low:+.3f}, {high:+.3f}]  "
            f"B wins in {wins:.0%} of draws"
        )


if __name__ == "__main__":
    main()
