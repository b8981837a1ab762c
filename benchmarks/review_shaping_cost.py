"""What shaping the draft for review costs against ``predict`` itself (issue 64: at most 5 %).

    .venv/bin/python benchmarks/review_shaping_cost.py [CITY] [--repeat 5]

CITY defaults to the 16-patch seed-7 test city (``csboundary synth DIR --seed 7 --split test
--tiles 2x2 --tile-size 2000``, made in a temporary folder). ``predict`` runs twice on it (the
first may prepare the ONNX networks once); the second's wall time is the reference. On its
graph.json the shaping steps are timed (the best of ``--repeat`` runs): seam bubbles dropped and
straight runs straightened (``graph/bubbles.py``, ``graph/straightening.py``: inside the city
graph's making, on a graph of the same size) and the review draft decided per boundary
(``metrics.review_time.review_draft``: in the writer).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from csboundary.graph import BoundaryGraph
from csboundary.graph.boundaries import graph_boundaries
from csboundary.graph.bubbles import drop_bubbles
from csboundary.graph.straightening import straighten
from csboundary.metrics.review_time import ReviewCosts, review_draft


def best_of(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city", nargs="?", type=Path)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    command = [sys.executable, "-m", "csboundary"]
    with tempfile.TemporaryDirectory() as tmp:
        city = args.city
        if city is None:
            city = Path(tmp) / "city"
            subprocess.run(
                [
                    *command,
                    "synth",
                    str(city),
                    "--seed",
                    "7",
                    "--split",
                    "test",
                    "--tiles",
                    "2x2",
                    "--tile-size",
                    "2000",
                    "--quiet",
                ],
                check=True,
            )
        walls = []
        for run in range(2):
            out = Path(tmp) / f"pred-{run}"
            start = time.perf_counter()
            subprocess.run(
                [*command, "predict", str(city), "--out", str(out), "--quiet"], check=True, capture_output=True
            )
            walls.append(time.perf_counter() - start)
        graph = BoundaryGraph.read_json(out / "graph.json")
        shape = best_of(args.repeat, lambda: straighten(drop_bubbles(graph)))
        costs = ReviewCosts()
        draft = best_of(args.repeat, lambda: review_draft(graph_boundaries(graph), costs, 0.152))
    print(f"{city}: {graph.n_edges} edges; predict {walls[1]:.2f} s wall (first run {walls[0]:.2f} s)")
    print(
        f"bubbles + straightening {shape * 1000:.0f} ms ({shape / walls[1]:.1%} of predict); "
        f"review draft {draft * 1000:.0f} ms ({draft / walls[1]:.1%}); together {(shape + draft) / walls[1]:.1%}"
    )


if __name__ == "__main__":
    main()
