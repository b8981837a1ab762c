"""SIGKILL a city run half-way, run the same command again: it must finish with the work of about
one run, and write the same graph.json as a run never interrupted (issue 14).

    .venv/bin/python benchmarks/resume_after_kill.py [CITY] [--at 0.5] [--work /tmp/resume-bench]

CITY defaults to data/cities/test-s1-1x1-5000 (25 patches; synthesized if missing). Prints the
uninterrupted run's time, when the kill came (windows done), the resumed run's work (patches
predicted and windows connected by each run, from summary.json) and the total work and time of
killed + resumed run against the uninterrupted one (acceptance: work at most 1.1x).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

STORE = ".csboundary-run"


def command(city: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "csboundary", "predict", str(city), "--out", str(out), "--device", "cpu", "--quiet"]


def windows_done(out: Path) -> int:
    folder = out / STORE / "graphs"
    return (
        sum(1 for p in folder.iterdir() if p.suffix == ".npz" and not p.name.startswith(".")) if folder.exists() else 0
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city", nargs="?", type=Path, default=Path("data/cities/test-s1-1x1-5000"))
    parser.add_argument("--at", type=float, default=0.5, help="kill when this share of the windows has its graph")
    parser.add_argument("--work", type=Path, default=Path("/tmp/resume-bench"))
    args = parser.parse_args()
    if not (args.city / "city.json").exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "csboundary",
                "synth",
                str(args.city),
                "--seed",
                "1",
                "--split",
                "test",
                "--tiles",
                "1x1",
                "--tile-size",
                "5000",
                "--quiet",
            ],
            check=True,
        )
    whole, killed = args.work / "uninterrupted", args.work / "killed"
    for folder in (whole, killed):
        subprocess.run(["rm", "-rf", str(folder)], check=True)

    start = time.perf_counter()
    subprocess.run(command(args.city, whole), check=True, capture_output=True)
    t_whole = time.perf_counter() - start
    n = json.loads((whole / "summary.json").read_text())["patches"]
    print(f"uninterrupted: {n} patches in {t_whole:.1f} s")

    start = time.perf_counter()
    job = subprocess.Popen(command(args.city, killed), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while windows_done(killed) < args.at * n:
        if job.poll() is not None:
            sys.exit("the run ended before it could be killed")
        time.sleep(0.02)
    os.kill(job.pid, signal.SIGKILL)
    job.wait()
    t_killed = time.perf_counter() - start
    at_kill = windows_done(killed)
    print(
        f"SIGKILL after {t_killed:.1f} s with {at_kill} of {n} windows done; graph.json written: {(killed / 'graph.json').exists()}"
    )

    start = time.perf_counter()
    subprocess.run(command(args.city, killed), check=True, capture_output=True)
    t_resumed = time.perf_counter() - start
    work = json.loads((killed / "summary.json").read_text())["work"]
    # the killed run's work: what the resumed run found done, plus at most one FPN batch and one window in flight
    fpn_total = work["patches_reused"] + 1 + work["patches_predicted"]
    windows_total = work["windows_reused"] + 1 + work["windows_connected"]
    same = (killed / "graph.json").read_bytes() == (whole / "graph.json").read_bytes()
    print(
        f"resumed in {t_resumed:.1f} s: reused {work['patches_reused']} patch maps and {work['windows_reused']} window graphs; "
        f"predicted {work['patches_predicted']} patches, connected {work['windows_connected']} windows"
    )
    print(
        f"total work, killed + resumed (counting one in-flight batch and window as lost): FPN {fpn_total / n:.2f}x, "
        f"windows {windows_total / n:.2f}x, time {(t_killed + t_resumed) / t_whole:.2f}x (limit 1.1x work); "
        f"graph.json identical: {same}"
    )


if __name__ == "__main__":
    main()
