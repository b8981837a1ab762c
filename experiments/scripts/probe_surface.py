"""Probe: can a road-surface head on the frozen shipped FPN see the roadway on real photographs?

    .venv/bin/python experiments/scripts/probe_surface.py OUT --cities 12 --steps 800

Builds synthetic cities of every style (the generator's ``roadway`` polygon is the target),
trains a small head on the shipped FPN's fused pyramid (FPN frozen), saves it, and writes the
surface probability of a few images as PNGs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import rasterio.features
import torch
import torch.nn.functional as F
from affine import Affine
from PIL import Image
from torch import nn

from csboundary.data import city_layout
from csboundary.data.raster import Mosaic
from csboundary.data.synth.city import plan_city, synthesize_city
from csboundary.data.synth.styles import STYLES, style_config
from csboundary.models.augmentation import AugmentConfig, flip_rotate90, photometric
from csboundary.models.checkpoint import load_fpn, shipped_weights
from csboundary.models.fpn import conv_bn_relu, top_down
from csboundary.models.maps import unit_bands

SIZE = 2500


def city_and_surface(cache: Path, style: str, seed: int) -> tuple[Path, np.ndarray]:
    config = style_config(style, tile_size=SIZE)
    path = cache / f"train-{style}-s{seed}-1x1-{SIZE}"
    if not city_layout.is_city_dir(path):
        synthesize_city(path, seed, "train", (1, 1), config, progress=False)
    plan = plan_city(config, "train", seed, (1, 1))
    frame = plan.frame(0, 0)
    transform = Affine(frame.gsd, 0, frame.x0, 0, -frame.gsd, frame.y1)
    roadway = plan.scene.network.roadway
    mask = rasterio.features.rasterize(
        [roadway], out_shape=(SIZE, SIZE), transform=transform, fill=0, default_value=1, dtype="uint8"
    )
    return path, mask


def fused_features(fpn, x: torch.Tensor) -> torch.Tensor:
    factor = round(1 / fpn.config.encoder_scale)
    small = F.avg_pool2d(x, factor)
    return top_down(fpn.encoder(small)[1:], fpn.lateral, fpn.smooth)


class SurfaceHead(nn.Module):
    def __init__(self, cin: int = 48, width: int = 32):
        super().__init__()
        self.body = nn.Sequential(conv_bn_relu(cin, width), conv_bn_relu(width, width), nn.Conv2d(width, 1, 1))

    def forward(self, fused: torch.Tensor, size) -> torch.Tensor:
        return F.interpolate(self.body(fused), size=size, mode="bilinear", align_corners=False)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("out", type=Path)
    p.add_argument("--cities", type=int, default=12)
    p.add_argument("--steps", type=int, default=800)
    p.add_argument("--crop", type=int, default=384)
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--images", nargs="*", default=[])
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    styles = list(STYLES)
    cities = []
    for i in range(args.cities):
        style = styles[i % len(styles)]
        path, mask = city_and_surface(Path("data/cities"), style, 2000 + i)
        mosaic = Mosaic.open(city_layout.tiles_dir(path))
        cities.append((mosaic, mask))
        print(f"city {i} {style} road share {mask.mean():.2f}", flush=True)
    fpn = load_fpn(shipped_weights(), "cpu").float()
    fpn.eval()
    for q in fpn.parameters():
        q.requires_grad_(False)
    head = SurfaceHead()
    opt = torch.optim.AdamW(head.parameters(), 1e-3, weight_decay=1e-4)
    aug = AugmentConfig()
    log = open(args.out / "log.jsonl", "w")
    start = time.time()
    for step in range(1, args.steps + 1):
        images, targets = [], []
        for _ in range(args.batch):
            mosaic, mask = cities[rng.integers(len(cities))]
            c, r = rng.integers(0, SIZE - args.crop, size=2)
            from csboundary.data.windows import PixelWindow

            img = unit_bands(mosaic.read(PixelWindow(int(c), int(r), args.crop, args.crop)).data)
            tgt = mask[r : r + args.crop, c : c + args.crop][None].astype(np.float32)
            img, tgt = flip_rotate90(rng, img, tgt)
            images.append(photometric(rng, img, aug))
            targets.append(tgt)
        x = torch.from_numpy(np.stack(images))
        y = torch.from_numpy(np.stack(targets))
        with torch.no_grad():
            fused = fused_features(fpn, x)
        logits = head(fused, x.shape[-2:])
        loss = F.binary_cross_entropy_with_logits(logits, y)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 50 == 0:
            with torch.no_grad():
                acc = ((logits > 0) == (y > 0.5)).float().mean().item()
            line = {
                "step": step,
                "loss": round(loss.item(), 4),
                "acc": round(acc, 4),
                "s": round(time.time() - start, 1),
            }
            print(json.dumps(line), flush=True)
            log.write(json.dumps(line) + "\n")
            log.flush()
    torch.save(head.state_dict(), args.out / "surface_head.pt")
    head.eval()
    for name in args.images:
        import rasterio

        with rasterio.open(name) as src:
            arr = src.read()[:3]
        arr = np.concatenate([arr, arr[1:2]])
        h, w = arr.shape[1:]
        arr = np.pad(arr, ((0, 0), (0, (-h) % 64), (0, (-w) % 64)), mode="edge")
        x = torch.from_numpy(unit_bands(arr))[None]
        with torch.no_grad():
            prob = torch.sigmoid(head(fused_features(fpn, x), x.shape[-2:]))[0, 0].numpy()[:h, :w]
        Image.fromarray((prob * 255).astype(np.uint8)).save(args.out / (Path(name).parent.parent.name + "-surface.png"))


if __name__ == "__main__":
    main()
