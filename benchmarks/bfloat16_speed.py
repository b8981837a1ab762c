"""The shipped FPN on one 1100 px window: float32, bfloat16 autocast, bfloat16 with batch norms folded.

    .venv/bin/python benchmarks/bfloat16_speed.py [--repeats 5] [--rounds 3]

PyTorch, channels-last input, this machine's threads; the three variants run in turn, ``--rounds``
times, so that a change in the machine's load falls on all of them. Prints the median of each
variant's timed runs (one warm-up each per round) and the largest probability difference to
float32. bfloat16 is fast only where the CPU has bfloat16 units (AMX or AVX512-BF16; see
``csboundary.models.device.bfloat16_hardware``, printed too).
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from csboundary.models.batchnorm_folding import fold_batch_norms
from csboundary.models.device import bfloat16_hardware
from csboundary.pipeline.prediction.patch import PatchPredictor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    fpn = PatchPredictor.load(None, torch.device("cpu")).fpn.eval()
    variants = {
        "float32": (fpn, False),
        "bfloat16": (fpn, True),
        "bfloat16, norms folded": (fold_batch_norms(fpn), True),
    }
    x = torch.rand(1, 4, 1100, 1100, generator=torch.Generator().manual_seed(0)).contiguous(
        memory_format=torch.channels_last
    )
    times = {name: [] for name in variants}
    outputs = {}
    with torch.inference_mode():
        for _ in range(args.rounds):
            for name, (model, half) in variants.items():
                with torch.autocast("cpu", dtype=torch.bfloat16, enabled=half):
                    outputs[name] = torch.sigmoid(model(x).float())
                    for _ in range(args.repeats):
                        start = time.perf_counter()
                        model(x)
                        times[name].append(time.perf_counter() - start)
    print(
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, bfloat16 units: {bfloat16_hardware(torch.device('cpu'))}, "
        f"median of {args.rounds} x {args.repeats} runs"
    )
    for name in variants:
        difference = float((outputs[name] - outputs["float32"]).abs().max())
        print(
            f"{name:24s} {statistics.median(times[name]):.3f} s per window, probabilities within {difference:.3f} of float32"
        )


if __name__ == "__main__":
    main()
