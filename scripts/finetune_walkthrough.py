"""The loop of docs/finetune.md on real crops, every step a csboundary command, timed:

    python scripts/finetune_walkthrough.py SET --out DIR [--cache data/cities]

1. predict every crop of the set with the shipped weights;
2. review one "district" (every other crop, starting with the second): a stand-in reviewer whose
   edits delete every predicted edge, draw every ground-truth line and mark the whole crop
   complete (a perfect review), applied with apply-review;
3. finetune on the reviewed prediction folders;
4. predict the rest with the tuned bundle, and score the rest with both bundles (evaluate-set).

Prints each step's wall time and the scores; DIR/walkthrough.json keeps them.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from csboundary.data.ground_truth import read_ground_truth
from csboundary.graph import BoundaryGraph
from csboundary.graph.chains import edge_line
from csboundary.pipeline.prediction.city_scores import set_cities


def cli(*args: str) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "csboundary", *args], check=True)
    return time.perf_counter() - start


def perfect_review(prediction: Path, city: Path) -> dict:
    """Edits that turn the prediction into the crop's ground truth, the whole crop complete."""
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    t = graph.transform
    world = lambda line: [[float(v) for v in t * (float(c), float(r))] for c, r in line]  # noqa: E731
    features = [
        {
            "type": "Feature",
            "properties": {"action": "delete", "edge": k},
            "geometry": {"type": "LineString", "coordinates": world(edge_line(graph, k))},
        }
        for k in range(graph.n_edges)
    ]
    for line in read_ground_truth(city / "ground_truth.gpkg", graph.crs).geometry:
        xy = np.asarray(line.coords)[:, :2]
        parts = (
            [xy[: len(xy) // 2 + 1], xy[len(xy) // 2 :]] if np.allclose(xy[0], xy[-1]) else [xy]
        )  # a ring: two halves
        features += [
            {
                "type": "Feature",
                "properties": {"action": "add"},
                "geometry": {"type": "LineString", "coordinates": p.tolist()},
            }
            for p in parts
            if len(p) >= 2
        ]
    width, height = json.loads((prediction / "summary.json").read_text())["mosaic_px"]
    ring = world([(0, 0), (width, 0), (width, height), (0, height), (0, 0)])
    features.append(
        {
            "type": "Feature",
            "properties": {"action": "complete"},
            "geometry": {"type": "Polygon", "coordinates": [ring]},
        }
    )
    return {
        "type": "FeatureCollection",
        "properties": {"crs": graph.crs, "tool": "scripts/finetune_walkthrough.py"},
        "features": features,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("set")
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--cache", default=None)
    args = parser.parse_args()
    cities = set_cities(args.set)
    district, rest = cities[1::2], cities[0::2]
    out = args.out
    seconds = {}
    seconds["predict district"] = sum(
        cli("predict", str(c), "--out", str(out / "pred" / c.name), "--quiet") for c in district
    )
    start = time.perf_counter()
    for city in district:
        pred = out / "pred" / city.name
        edits = out / "edits" / f"{city.name}.geojson"
        edits.parent.mkdir(parents=True, exist_ok=True)
        edits.write_text(json.dumps(perfect_review(pred, city)))
        cli("apply-review", str(pred), str(edits))
    seconds["apply-review district"] = time.perf_counter() - start
    cache = ["--cache", args.cache] if args.cache else []
    seconds["finetune"] = cli(
        "finetune", *[str(out / "pred" / c.name) for c in district], "--out", str(out / "tuned.pt"), *cache
    )
    seconds["predict rest (tuned)"] = sum(
        cli("predict", str(c), "--out", str(out / "pred-tuned" / c.name), "--weights", str(out / "tuned.pt"), "--quiet")
        for c in rest
    )
    rest_set = out / "rest"
    rest_set.mkdir(exist_ok=True)
    for city in rest:
        link = rest_set / city.name
        if not link.exists():
            link.symlink_to(city.resolve())
    cli("evaluate-set", str(rest_set), "--json", str(out / "rest-base.json"), "--quiet")
    cli(
        "evaluate-set",
        str(rest_set),
        "--weights",
        str(out / "tuned.pt"),
        "--json",
        str(out / "rest-tuned.json"),
        "--quiet",
    )
    scores = {name: json.loads((out / f"rest-{name}.json").read_text())["mean"] for name in ("base", "tuned")}
    record = {
        "district": [c.name for c in district],
        "rest": [c.name for c in rest],
        "seconds": seconds,
        "rest_scores": {k: {m: v[m] for m in ("precision@5", "f1@5", "apls", "tlts")} for k, v in scores.items()},
    }
    (out / "walkthrough.json").write_text(json.dumps(record, indent=1) + "\n")
    print(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
