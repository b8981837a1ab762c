"""How well an FPN's road-surface head tells roadway from lawns, drives and roofs on the Ottawa crops.

    python experiments/scripts/probe_surface_ottawa.py WEIGHTS [WEIGHTS...] [--crops /tmp/ottawa]
        [--labels ../shared/data/real/ottawa-roadnet]

The crops' label pictures (``<id>_edge.png``) paint the roadway in blue, cyan or magenta beside
the green edge lines; that roadway, resized to the imported crop (``csboundary import-masks``,
707 px), is the truth here. Prints the surface IoU at 0.5, the mean surface probability on
roadway and off it, and the share of off-road pixels above 0.5 (validation only: the crops are
never trained on; the 13 numbered crops, as the demo crop's picture paints no roadway). The
measurement behind the surface negatives (docs/experiments.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import rasterio
import torch

from csboundary.models.checkpoint import load_fpn


def roadway(labels: Path, crop_id: str, size: int) -> np.ndarray:
    """(size, size) bool: the roadway painted in the crop's label picture."""
    rgb = cv2.imread(str(labels / f"{crop_id}_edge.png"))[..., ::-1].astype(int)
    road = ((rgb[..., 2] > 128) & (rgb.sum(axis=2) > 200)).astype(np.uint8)  # blue, cyan, magenta
    return cv2.resize(road, (size, size), interpolation=cv2.INTER_NEAREST).astype(bool)


@torch.no_grad()
def surface_scores(weights: str, crops: Path, labels: Path) -> str:
    fpn = load_fpn(weights, torch.device("cpu")).eval()
    inter = union = 0
    on, off = [], []
    # the 13 numbered crops (the demo crop's picture is red lines on white: no roadway painted)
    for crop in sorted(
        p for p in crops.iterdir() if p.is_dir() and p.name[0].isdigit() and (labels / f"{p.name}_edge.png").exists()
    ):
        with rasterio.open(next((crop / "tiles").glob("*.tif"))) as src:
            image = src.read().astype(np.float32) / 255
        image = np.concatenate([image[:3], image[1:2]])[None]  # RGB, NIR := green
        surface = torch.sigmoid(fpn(torch.from_numpy(image))[0, 2]).numpy()
        road = roadway(labels, crop.name, surface.shape[0])
        inter += int((surface > 0.5)[road].sum())
        union += int(((surface > 0.5) | road).sum())
        on.append(surface[road])
        off.append(surface[~road])
    on, off = np.concatenate(on), np.concatenate(off)
    return (
        f"{weights}: surface IoU {inter / max(union, 1):.3f}, mean on roadway {on.mean():.2f}, off it {off.mean():.2f}, "
        f"off-road share above 0.5 {np.mean(off > 0.5):.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("weights", nargs="+")
    parser.add_argument("--crops", type=Path, default=Path("/tmp/ottawa"))
    parser.add_argument("--labels", type=Path, default=Path("../shared/data/real/ottawa-roadnet"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    for weights in args.weights:
        print(surface_scores(weights, args.crops, args.labels), flush=True)


if __name__ == "__main__":
    main()
