"""``adapt`` and ``predict`` on 8 tiles scattered over a city against the same 8 side by side (issue 65).

    .venv/bin/python benchmarks/scattered_tiles.py [--city /tmp/sc/city] [--work /tmp/scattered] [--steps 30]

Cuts 8 tiles of 1000 px from a synthetic city of at least 4000 x 2000 px (``csboundary synth
/tmp/sc/city --seed 7 --split test --tiles 1x1 --tile-size 4000``) and writes them twice, in the
city's CRS: side by side (a 4000 x 2000 px mosaic), and scattered over 58 km (the mosaic's bounding
box is 382,000 px square: 146 G pixels for 8 M pixels of imagery). Runs ``csboundary adapt`` (STEPS
FPN steps, no AfANet step, one synthetic city, shared cache) and ``csboundary predict`` on each
folder in a fresh process, and prints seconds per FPN step, whole-run seconds and peak memory.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import rasterio
from affine import Affine
from rasterio.windows import Window

SIDE = 1000
SPREAD = 382_000  # px: the scattered mosaic's bounding box
PLACES = [
    (0, 0),
    (51_000, 300_000),
    (120_000, 77_000),
    (199_000, 381_000 - SIDE),
    (250_000, 160_000),
    (302_000, 12_000),
    (340_000, 240_000),
    (381_000 - SIDE, 330_000),
]  # (col, row) of each tile's corner, px


def write_tiles(city: Path, out: Path, scattered: bool) -> Path:
    """The 8 tiles of ``city``'s first two tile rows, side by side or at :data:`PLACES`."""
    source = sorted((city / "tiles").glob("*.tif"))[0]
    out.mkdir(parents=True, exist_ok=True)
    with rasterio.open(source) as src:
        t = src.transform
        for k in range(8):
            row, col = divmod(k, 4)
            data = src.read(window=Window(col * SIDE, row * SIDE, SIDE, SIDE))
            c, r = PLACES[k] if scattered else (col * SIDE, row * SIDE)
            profile = dict(
                src.profile,
                width=SIDE,
                height=SIDE,
                transform=t * Affine.translation(c, r),
                tiled=True,
                blockxsize=256,
                blockysize=256,
                compress="deflate",
            )
            with rasterio.open(out / f"tile-{k}.tif", "w", **profile) as dst:
                dst.write(data)
    return out


PEAK = (
    "import resource, subprocess, sys; code = subprocess.run(sys.argv[1:]).returncode; "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr); sys.exit(code)"
)


def timed(command: list[str]) -> tuple[float, float, str]:
    """Seconds, peak resident MB of the command (measured by a process of its own) and its last stderr line."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", PEAK, *command], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    lines = done.stderr.strip().splitlines()
    last = lines[-2] if len(lines) > 1 else ""
    if done.returncode != 0:
        print(f"{' '.join(command)}: exit {done.returncode}: {last}")
    return seconds, int(lines[-1]) / 1024, last


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--city", type=Path, default=Path("/tmp/sc/city"))
    parser.add_argument("--work", type=Path, default=Path("/tmp/scattered"))
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--skip-predict", action="store_true")
    args = parser.parse_args()
    cli = [sys.executable, "-m", "csboundary"]
    rows = []
    for name in ("scattered", "side"):
        folder = write_tiles(args.city, args.work / name, name == "scattered")
        work = args.work / f"adapt-{name}"
        shutil.rmtree(work, ignore_errors=True)
        (args.work / f"{name}.pt").unlink(missing_ok=True)
        seconds, peak, last = timed(
            cli
            + [
                "adapt",
                str(folder),
                "--out",
                str(args.work / f"{name}.pt"),
                "--work",
                str(work),
                "--fpn-steps",
                str(args.steps),
                "--afanet-steps",
                "0",
                "--synthetic-cities",
                "1",
                "--cache",
                str(args.work / "synthetic"),
                "--quiet",
                "--device",
                "cpu",
            ]
        )
        row = {"layout": name, "adapt_s": round(seconds, 1), "adapt_peak_mb": round(peak)}
        log = work / "fpn" / "train.log"
        if (
            log.exists()
        ):  # seconds per step: the log's first and last event, so set-up before the first step is left out
            events = [json.loads(line) for line in log.read_text().splitlines()]
            span = datetime.fromisoformat(events[-1]["time"]) - datetime.fromisoformat(events[0]["time"])
            row["adapt_s_per_step"] = round(span.total_seconds() / args.steps, 2)
        row["adapt_last"] = last
        if not args.skip_predict:
            seconds, peak2, last = timed(
                cli + ["predict", str(folder), "--out", str(args.work / f"pred-{name}"), "--quiet", "--restart"]
            )
            row.update(predict_s=round(seconds, 1), predict_peak_mb=round(peak2))
            summary = args.work / f"pred-{name}" / "summary.json"
            if summary.exists():
                row["patches"] = json.loads(summary.read_text()).get("patches")
        rows.append(row)
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
