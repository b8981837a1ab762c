"""``predict --scheduler`` on a stock Dask cluster against the local run (issue 14).

    .venv/bin/python benchmarks/dask_cluster.py [CITY] [--threads 2] [--work /tmp/dask-bench]

Starts ``dask scheduler`` and worker processes with the stock commands, on this machine, and runs
the same city (default data/cities/test-s1-1x1-5000, 25 patches) four ways at the same total
number of torch threads (THREADS):

* local, one process with THREADS threads (the default way to run);
* local, one process with 1 thread (the FPN's numbers of a 1-thread worker);
* the cluster with 1 worker of THREADS threads, and with THREADS workers of 1 thread;
* the latter again, with one worker process killed (SIGKILL) when half the windows are done: its
  nanny starts a new one, the scheduler reruns its in-flight tasks.

Prints each run's time, time per patch and km2/h, each worker's and the scheduler's peak resident
memory, and whether graph.json equals the local run's at the same threads per process.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

BIN = Path(sys.executable).parent


def peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def predict(city: Path, out: Path, *extra: str) -> tuple[dict, float]:
    start = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "csboundary",
            "predict",
            str(city),
            "--out",
            str(out),
            "--device",
            "cpu",
            "--quiet",
            "--restart",
            *extra,
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads((out / "summary.json").read_text()), time.perf_counter() - start


def predict_killing_a_worker(city: Path, out: Path, address: str, threads: int) -> tuple[dict, float]:
    import signal

    from distributed import Client

    with Client(address) as client:
        victim = sorted(client.run(os.getpid).values())[0]
    start = time.perf_counter()
    job = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "csboundary",
            "predict",
            str(city),
            "--out",
            str(out),
            "--device",
            "cpu",
            "--quiet",
            "--restart",
            "--scheduler",
            address,
            "--threads",
            str(threads),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    graphs = out / ".csboundary-run" / "graphs"
    while not graphs.exists() or len(list(graphs.glob("*.npz"))) < 12:
        time.sleep(0.05)
    os.kill(victim, signal.SIGKILL)
    print(f"killed worker process {victim} with {len(list(graphs.glob('*.npz')))} windows done", flush=True)
    if job.wait() != 0:
        sys.exit("the run with a killed worker failed")
    return json.loads((out / "summary.json").read_text()), time.perf_counter() - start


def cluster(work: Path, workers: int, threads: int):
    """A scheduler and ``workers`` worker processes of ``threads`` torch threads, started as a user would."""
    scheduler_file = work / f"scheduler-{workers}.json"
    scheduler_file.unlink(missing_ok=True)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    procs = [
        subprocess.Popen(
            [
                str(BIN / "dask"),
                "scheduler",
                "--scheduler-file",
                str(scheduler_file),
                "--port",
                "0",
                "--dashboard-address",
                ":0",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    while not scheduler_file.exists():
        time.sleep(0.1)
    procs += [
        subprocess.Popen(
            [
                str(BIN / "dask"),
                "worker",
                "--scheduler-file",
                str(scheduler_file),
                "--nthreads",
                "1",
                "--nworkers",
                "1",
                "--no-dashboard",
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for _ in range(workers)
    ]
    address = json.loads(scheduler_file.read_text())["address"]
    from distributed import Client

    with Client(address) as client:
        client.wait_for_workers(workers, timeout=120)
    return address, procs


def same_files(a: Path, b: Path) -> bool:
    """graph.json and the GeoJSON byte for byte, and every feature of both GeoPackage layers."""
    import pyogrio

    if any((a / name).read_bytes() != (b / name).read_bytes() for name in ("graph.json", "boundaries.geojson")):
        return False
    return all(
        pyogrio.read_dataframe(a / "boundaries.gpkg", layer=layer).equals(
            pyogrio.read_dataframe(b / "boundaries.gpkg", layer=layer)
        )
        for layer in ("road_boundaries", "edges")
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city", nargs="?", type=Path, default=Path("data/cities/test-s1-1x1-5000"))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--work", type=Path, default=Path("/tmp/dask-bench"))
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    t = args.threads
    rows = []
    for name, extra in (
        (f"local, 1 process x {t} threads", ("--threads", str(t))),
        ("local, 1 process x 1 thread", ("--threads", "1")),
    ):
        summary, wall = predict(args.city, args.work / f"local-{extra[1]}", *extra)
        rows.append((name, summary, wall, f"local-{extra[1]}", {}))
    for workers, threads, kill in ((1, t, False), (t, 1, False), (t, 1, True)):
        address, procs = cluster(args.work, workers, threads)
        folder = f"dask-{workers}x{threads}{'-killed' if kill else ''}"
        try:
            if kill:
                summary, wall = predict_killing_a_worker(args.city, args.work / folder, address, threads)
            else:
                summary, wall = predict(
                    args.city, args.work / folder, "--scheduler", address, "--threads", str(threads)
                )
            from distributed import Client

            with Client(address) as client:
                memory = {
                    "workers": sorted(round(v) for v in client.run(peak_rss_mb).values()),
                    "scheduler": round(client.run_on_scheduler(peak_rss_mb)),
                }
        finally:
            for p in reversed(procs):
                p.terminate()
            for p in procs:
                p.wait(timeout=60)
        reference = f"local-{threads}"
        name = f"dask, {workers} worker(s) x {threads} thread(s){', one killed' if kill else ''}"
        rows.append((name, summary, wall, folder, memory, reference))
    for row in rows:
        name, summary, wall, folder, memory = row[:5]
        n = summary["patches"]
        line = (
            f"{name:34s} {wall:6.1f} s wall, {summary['seconds']['total'] / n:.3f} s/patch, {summary['km2_per_hour']:7.2f} km2/h, "
            f"client peak RSS {summary['peak_rss_mb']['total']:.0f} MB"
        )
        if memory:
            same = same_files(args.work / folder, args.work / row[5])
            line += (
                f"; worker peak RSS {memory['workers']} MB, scheduler {memory['scheduler']} MB; graph.json, GeoJSON and every "
                f"GeoPackage feature == {row[5]}: {same}"
            )
        print(line, flush=True)


if __name__ == "__main__":
    main()
