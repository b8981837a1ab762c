"""Where the EfficientNet-Lite0 FPN spends its time at 1100 px, and the light head against the full one.

    .venv/bin/python benchmarks/fpn_head_speed.py [--repeat 5]

PyTorch, channels-last, no gradients, untrained weights (time does not depend on them). Prints the
seconds of each part of the full-head FPN (encoder, top-down path, stride-2 stem, upsampling and
concatenation, head, final upsampling) on the padded 1152 px input, then the whole FPN per
1100 px patch for the full head and for ``head="light"`` with a 16- or 24-channel stem.
"""

import argparse
import time

import torch
import torch.nn.functional as F

from csboundary.models.fpn import FPN, FPNConfig, top_down


def seconds(fn, repeat: int) -> float:
    fn()
    start = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - start) / repeat


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    torch.set_grad_enabled(False)
    cl = torch.channels_last
    full = FPN(FPNConfig(backbone="efficientnet-lite0", pretrained=False)).eval().to(memory_format=cl)
    x = torch.rand(1, 4, 1152, 1152).to(memory_format=cl)  # 1100 px padded to the stride (64)
    small = F.avg_pool2d(x, 2)
    features = full.encoder(small)[1:]
    fused = top_down(features, full.lateral, full.smooth)
    stem = full.stem((x - 0.5) / 0.25)
    joined = torch.cat([F.interpolate(fused, size=stem.shape[-2:], mode="bilinear", align_corners=False), stem], 1)
    logits = full.head(joined)
    parts = {
        "encoder": lambda: full.encoder(small),
        "top-down path": lambda: top_down(features, full.lateral, full.smooth),
        "stride-2 stem": lambda: full.stem((x - 0.5) / 0.25),
        "upsample + concat": lambda: torch.cat(
            [F.interpolate(fused, size=stem.shape[-2:], mode="bilinear", align_corners=False), stem], 1
        ),
        "head": lambda: full.head(joined),
        "final upsample": lambda: F.interpolate(logits, scale_factor=2, mode="bilinear", align_corners=False),
    }
    for name, fn in parts.items():
        print(f"full head, {name:18s} {seconds(fn, args.repeat):.3f} s")
    patch = torch.rand(1, 4, 1100, 1100).to(memory_format=cl)
    for label, overrides in (
        ("full head", {}),
        ("light head, stem 16", {"head": "light", "stem": 16}),
        ("light head, stem 24", {"head": "light", "stem": 24}),
    ):
        model = FPN(FPNConfig(backbone="efficientnet-lite0", pretrained=False, **overrides)).eval().to(memory_format=cl)
        print(f"FPN, {label:20s} {seconds(lambda model=model: model(patch), args.repeat):.3f} s per 1100 px patch")


if __name__ == "__main__":
    main()
