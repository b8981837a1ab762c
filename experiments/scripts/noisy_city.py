"""Experiment: a copy of a labelled city whose tiles carry an imperceptible noise, to measure how far
the city-scale scores move when the maps change as little as an int8 network changes them.

    .venv/bin/python experiments/scripts/noisy_city.py CITY... --out data/cities-noisy [--amplitude 1] [--seed 0]

Every pixel of every band gets an integer drawn uniformly from -A..A (A = ``--amplitude`` grey
levels, default 1; clipped to 0..255; seeded per tile), the ground truth and city.json are copied
as they are. Score both with ``precision_scores.py`` (float32): the change is what the metrics do
when the input changes by less than any camera's noise, the floor against which another
arithmetic's change (int8) is read.
"""

from __future__ import annotations

import argparse
import shutil
import zlib
from pathlib import Path

import numpy as np
import rasterio


def with_noise(data: np.ndarray, amplitude: int, rng: np.random.Generator) -> np.ndarray:
    """uint8 ``data`` with an integer drawn uniformly from -amplitude..amplitude added to every value, clipped to 0..255."""
    return np.clip(data.astype(np.int16) + rng.integers(-amplitude, amplitude + 1, size=data.shape), 0, 255).astype(
        np.uint8
    )


def noisy_copy(city: Path, out: Path, amplitude: int, seed: int) -> Path:
    target = out / city.name
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(city, target)
    for tile in sorted((target / "tiles").glob("*.tif")):
        rng = np.random.default_rng([seed, zlib.crc32(tile.name.encode())])
        with rasterio.open(tile, "r+") as dataset:
            dataset.write(with_noise(dataset.read(), amplitude, rng))
    return target


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("cities", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--amplitude", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for city in args.cities:
        print(noisy_copy(city, args.out, args.amplitude, args.seed), flush=True)


if __name__ == "__main__":
    main()
