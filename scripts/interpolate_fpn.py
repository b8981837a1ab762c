"""A fine-tuned FPN interpolated towards the FPN it started from (csboundary/models/weight_interpolation.py).

    python scripts/interpolate_fpn.py START TUNED --alpha 0.7 --out FPN.pt

START is the bundle or fpn checkpoint the fine-tune began at (its ``init_fpn``), TUNED the
fine-tuned fpn checkpoint; the result is an fpn checkpoint for ``csboundary bundle-weights``.
"""

from __future__ import annotations

import argparse

from csboundary.models.weight_interpolation import interpolate_fpn


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("start")
    parser.add_argument("tuned")
    parser.add_argument("--alpha", type=float, required=True, help="0 = START, 1 = TUNED")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    print(interpolate_fpn(args.start, args.tuned, args.alpha, args.out))


if __name__ == "__main__":
    main()
