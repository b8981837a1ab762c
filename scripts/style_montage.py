"""The picture of docs/styles.md: one 304 m tile of a test city per style, with its ground truth.

    python scripts/style_montage.py --out docs/styles.jpg

Uses (and builds if missing) the test cities of experiments/scripts/evaluate_styles.py.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import rasterio
from evaluate_styles import STYLES, city_dir

from csboundary.data.ground_truth import read_ground_truth

# the scored styles, then those only drawn here (not in experiments/scripts/evaluate_styles.py's tables yet)
MONTAGE_STYLES = (*STYLES, *(s for s in ("dense",) if s not in STYLES))
TILE = {"highway": "tile_r00_c01.tif"}  # the seed-7 highway city's interchange lies in its top-right tile


def crop_with_truth(city: Path, size: int = 2000, side: int = 480, tile: str = "tile_r00_c00.tif") -> np.ndarray:
    """A tile's top-left ``size`` px with the ground truth drawn in magenta, ``side`` px wide."""
    with rasterio.open(city / "tiles" / tile) as src:
        rgb = src.read((1, 2, 3)).transpose(1, 2, 0).copy()
        inverse = ~src.transform
        crs = src.crs
    for line in read_ground_truth(city / "ground_truth.gpkg", crs).geometry:
        for part in getattr(line, "geoms", [line]):
            cols, rows = inverse * np.asarray(part.coords).T
            cv2.polylines(
                rgb, [np.stack([cols, rows], 1).round().astype(np.int32)], False, (255, 0, 255), 2, cv2.LINE_AA
            )
    return cv2.resize(rgb[:size, :size], (side, side), interpolation=cv2.INTER_AREA)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/styles.jpg"))
    parser.add_argument("--cache", type=Path, default=Path("data/cities"))
    args = parser.parse_args()
    tiles = []
    for style in MONTAGE_STYLES:
        image = crop_with_truth(city_dir(style, args.cache), tile=TILE.get(style, "tile_r00_c00.tif"))
        cv2.putText(image, style, (12, 36), cv2.FONT_HERSHEY_SIMPLEX, 1.1, (0, 0, 0), 5, cv2.LINE_AA)
        cv2.putText(image, style, (12, 36), cv2.FONT_HERSHEY_SIMPLEX, 1.1, (255, 255, 255), 2, cv2.LINE_AA)
        tiles.append(image)
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % 3)  # fill the last row
    rows = [np.hstack(tiles[i : i + 3]) for i in range(0, len(tiles), 3)]
    cv2.imwrite(str(args.out), np.vstack(rows)[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 85])
    print(f"{args.out}: {len(MONTAGE_STYLES)} styles")


if __name__ == "__main__":
    main()
