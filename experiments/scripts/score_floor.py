"""Experiment: how often a perturbation moves a city's scores by more than a tolerance, against the
float32 scores of the same cities: int8 against imperceptible input noise.

    .venv/bin/python experiments/scripts/score_floor.py runs/precision float32-2 \
        int8-2=runs/precision noise1-s0=runs/precision-noisy1:float32-2 noise1-s1=runs/precision-noisy1s1:float32-2

The reference is ``REF_DIR/<config>-<city>.json`` (as ``precision_scores.py`` writes them); each
other argument is NAME=DIR[:CONFIG] (CONFIG defaults to NAME) over the same city names. Prints,
per perturbation: each city's change in F1@5 / APLS / TLTS, the cities where any change exceeds
``--tolerance`` (0.01), the largest and the mean absolute change and the mean change per metric with its 95 %
interval (paired bootstrap over the cities).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from precision_scores import METRICS, city_metrics  # experiments/scripts/, beside this script

from csboundary.metrics.compare import paired_bootstrap


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("ref_dir", type=Path)
    parser.add_argument("ref_config")
    parser.add_argument("others", nargs="+")
    parser.add_argument("--tolerance", type=float, default=0.01)
    args = parser.parse_args()
    reference = {
        p.name.removeprefix(args.ref_config + "-").removesuffix(".json"): city_metrics(p)
        for p in sorted(args.ref_dir.glob(f"{args.ref_config}-*.json"))
    }
    for other in args.others:
        name, _, where = other.partition("=")
        folder, _, config = where.partition(":")
        config = config or name
        deltas, pairs = {}, {m: ([], []) for m in METRICS}
        for city, base in reference.items():
            path = Path(folder) / f"{config}-{city}.json"
            if path.exists():
                scores = city_metrics(path)
                deltas[city] = {m: scores[m] - base[m] for m in METRICS}
                for m in METRICS:
                    pairs[m][0].append(base[m])
                    pairs[m][1].append(scores[m])
        print(f"{name} ({len(deltas)} cities)")
        for city, d in deltas.items():
            print(f"  {city:32s} " + " ".join(f"{d[m]:+.3f}" for m in METRICS))
        over = [c for c, d in deltas.items() if any(abs(v) > args.tolerance for v in d.values())]
        print(f"  cities with a change over {args.tolerance}: {len(over)} of {len(deltas)}")
        for m in METRICS:
            values = [abs(d[m]) for d in deltas.values()]
            mean, low, high, _ = paired_bootstrap(*pairs[m])
            print(
                f"  {m}: largest |change| {max(values):.3f}, mean |change| {sum(values) / len(values):.4f}, "
                f"mean change {mean:+.4f} [{low:+.4f}, {high:+.4f}], "
                f"over {args.tolerance}: {sum(v > args.tolerance for v in values)}"
            )


if __name__ == "__main__":
    main()
