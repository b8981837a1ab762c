"""Experiment: how far a precision moves the city-scale scores, against how far float32 itself moves.

    .venv/bin/python experiments/scripts/precision_scores.py --out runs/precision CITY... [--configs float32-2,float32-1,int8-2]

Each config is PRECISION-THREADS: ``evaluate-model CITY --engine onnx --precision PRECISION`` with
OMP_NUM_THREADS=THREADS (ONNX Runtime takes its thread count from PyTorch's). float32 on one
thread against two is the same network with its sums in another order: the change any other
arithmetic (an int8 network, another CPU) must be judged against. Prints F1@5, APLS and TLTS at
city scale per city and config, and each config's change from the first. Results already in OUT
are reused.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

METRICS = ("f1@5", "apls", "tlts")


def city_metrics(path: Path) -> dict[str, float]:
    """F1@5, APLS and TLTS at city scale from an ``evaluate-model --json`` file."""
    data = json.loads(path.read_text())
    metrics = data["city"]["metrics"] if "city" in data else data["scales"]["city"]["metrics"]
    return {m: float(metrics[m]) for m in METRICS}


def scores(city: Path, config: str, out: Path) -> dict:
    precision, threads = config.split("-")
    target = out / f"{config}-{city.name}.json"
    if not target.exists():
        env = dict(os.environ, OMP_NUM_THREADS=threads)
        subprocess.run(
            [
                sys.executable,
                "-m",
                "csboundary",
                "evaluate-model",
                str(city),
                "--engine",
                "onnx",
                "--precision",
                precision,
                "--device",
                "cpu",
                "--json",
                str(target),
                "--quiet",
            ],
            check=True,
            env=env,
            capture_output=True,
        )
    return city_metrics(target)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("cities", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--configs", default="float32-2,float32-1,int8-2")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    configs = args.configs.split(",")
    worst = {c: {m: 0.0 for m in METRICS} for c in configs[1:]}
    print("city".ljust(30) + "".join(f"{c:>26s}" for c in configs))
    for city in args.cities:
        rows = {c: scores(city, c, args.out) for c in configs}
        base = rows[configs[0]]
        cells = [" ".join(f"{rows[configs[0]][m]:.3f}" for m in METRICS)]
        for c in configs[1:]:
            delta = {m: rows[c][m] - base[m] for m in METRICS}
            for m in METRICS:
                worst[c][m] = max(worst[c][m], abs(delta[m]))
            cells.append(" ".join(f"{delta[m]:+.3f}" for m in METRICS))
        print(city.name.ljust(30) + "".join(f"{cell:>26s}" for cell in cells), flush=True)
    for c in configs[1:]:
        print(f"largest |change| {c} against {configs[0]}: " + ", ".join(f"{m} {v:.3f}" for m, v in worst[c].items()))
    from csboundary.metrics.compare import paired_bootstrap

    for c in configs[
        1:
    ]:  # the decision's criterion: the mean change over cities, with its 95 % paired-bootstrap interval
        cells = []
        for m in METRICS:
            a = [scores(city, configs[0], args.out)[m] for city in args.cities]
            b = [scores(city, c, args.out)[m] for city in args.cities]
            diff, low, high, _ = paired_bootstrap(a, b, seed=0)
            cells.append(f"{m} {diff:+.4f} [{low:+.4f}, {high:+.4f}]")
        print(f"mean change {c} - {configs[0]} over {len(args.cities)} cities: " + ", ".join(cells))


if __name__ == "__main__":
    main()
