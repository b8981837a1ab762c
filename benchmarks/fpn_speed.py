"""FPN time per 1100 px patch on this machine, eager and channels-last, for every FPN in one run.

    python benchmarks/fpn_speed.py [--repeats 5] [--weights W ...]

Compares the from-scratch ResNet FPN (the first shipped model) with the EfficientNet-Lite0 FPN
(shipped until 2026-12-03) and the larger Lite1 / Lite2 encoders (Lite2 ships since) at the same input, so the ratio is
measured under the same machine load.
Prints seconds per patch (median of ``--repeats`` after one warm-up) and the ratio to the first.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from csboundary.models.fpn import FPN, FPNConfig


def seconds_per_patch(model: torch.nn.Module, x: torch.Tensor, repeats: int) -> float:
    with torch.no_grad():
        model(x)
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            model(x)
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--size", type=int, default=1100)
    args = parser.parse_args()
    torch.manual_seed(0)
    x = torch.rand(1, 4, args.size, args.size)
    models = {
        "resnet (scratch, first shipped)": FPNConfig(),
        "efficientnet-lite0 @0.5 (until 12-03)": FPNConfig(backbone="efficientnet-lite0", pretrained=False),
        "efficientnet-lite0 @1.0": FPNConfig(backbone="efficientnet-lite0", encoder_scale=1.0, pretrained=False),
        "efficientnet-lite1 @0.5": FPNConfig(backbone="efficientnet-lite1", pretrained=False),
        "efficientnet-lite2 @0.5 (shipped)": FPNConfig(backbone="efficientnet-lite2", pretrained=False),
    }
    print(
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, {args.size}x{args.size} px, median of {args.repeats}"
    )
    print(f"{'FPN':36s} {'params':>9s} {'eager s':>9s} {'ch-last s':>10s} {'eager x':>8s} {'ch-last x':>10s}")
    base = None
    for name, config in models.items():
        model = FPN(config).eval()
        eager = seconds_per_patch(model, x, args.repeats)
        model = model.to(memory_format=torch.channels_last)
        last = seconds_per_patch(model, x.contiguous(memory_format=torch.channels_last), args.repeats)
        base = base or (eager, last)
        params = sum(p.numel() for p in model.parameters())
        print(
            f"{name:36s} {params / 1e6:8.2f}M {eager:9.3f} {last:10.3f} {eager / base[0]:8.2f} {last / base[1]:10.2f}"
        )


if __name__ == "__main__":
    main()
