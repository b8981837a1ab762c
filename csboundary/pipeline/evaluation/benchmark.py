"""The paper's comparison (Section V-D, Tables I-IV, Fig. 7) on one synthetic test city.

Every method runs through the same city pipeline (streaming map averaging, patch graphs,
stitching) and the same metrics; only the :class:`PatchModel` differs. Rows:

* csBoundary: the shipped bundle (FPN + AfANet), its graph AfANet's (the roadway outline off);
* Table IV, the ablation: AfANet retrained in full, with ``use_global=False`` and with
  ``use_local=False``, all three with the same reduced budget (1000 steps: the 2-core machine's
  limit) on the same FPN (the first shipped one, kept as ``ablation/fpn-first.pt`` with that
  bundle's inference settings), so the rows compare like with like;
* OrientationRefine, Sat2Graph, Enhanced-iCurb (Tables I-III): the baselines, each trained by
  ``csboundary train <method> --config configs/paper/<method>.json``.

Weights are looked up in ``weights_dir`` (the package's shipped ``weights/``; baselines under
``baselines/``, ablation variants under ``ablation/``), each with its ``*-train.log`` beside it
(training time for Table III). A method without weights is reported as missing, not guessed.

Table III's "epoch" is one pass over the train city's area (10000 x 10000 px for the shipped
recipe) in training samples: ``area / (batch * crop^2)`` steps for the dense networks,
``area / window^2`` for AfANet, whose every step sees one 1100 px window, and
``area / (batch * roi^2)`` for the iCurb agent's batches of ROIs.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Callable

import numpy as np

from csboundary.data.atomic import atomic_path
from csboundary.pipeline.prediction.options import PredictionOptions

TABLE_METRICS = [
    "precision@2",
    "precision@5",
    "precision@10",
    "recall@2",
    "recall@5",
    "recall@10",
    "f1@2",
    "f1@5",
    "f1@10",
    "apls",
    "tlts",
]


@dataclass
class Method:
    name: str  # the table's row label
    key: str  # file stem
    family: str
    loader: Callable  # (weights_dir, device) -> PatchModel
    logs: list[str]  # training logs (relative to weights_dir) whose durations add up to its training
    table: str = "comparison"  # comparison | ablation


def _csboundary(weights_dir: Path, device):
    """The shipped bundle with the roadway outline off: the paper's pipeline, whose graph is
    AfANet's (``predict`` adds the outline where the bundle sets it; graph/outline_fusion.py)."""
    from csboundary.pipeline.prediction.patch import PatchPredictor

    predictor = PatchPredictor.load(weights_dir / "csboundary-synthetic.pt", device)
    predictor.settings = dataclasses.replace(
        predictor.settings, outline=dataclasses.replace(predictor.settings.outline, sure=0.0)
    )
    return predictor


def _repository_weights(path: Path) -> Path:
    """A baseline's or ablation's weights: they come with a checkout of the repository, not with
    the wheel (``predict`` never loads them)."""
    if not path.exists():
        raise FileNotFoundError(
            f"{path} is not in this installation: the benchmark's baseline and ablation weights come with "
            "the repository (git clone; csboundary/weights/ablation and baselines), not with the wheel"
        )
    return path


FIRST_FPN = "ablation/fpn-first.pt"  # the FPN Table IV's AfANets were trained on (the first shipped one)
FIRST_INFERENCE = {"edge_threshold": 0.3, "max_degree": 2}  # that bundle's settings (no edge-support check)


def _ablation(variant: str):
    """Table IV's AfANets on the FPN they were trained on, with that bundle's inference settings:
    the ablation studies AfANet's two features and stays comparable across FPN upgrades."""

    def load(weights_dir: Path, device):
        from csboundary.pipeline.prediction.patch import PatchPredictor

        predictor = PatchPredictor.load(
            _repository_weights(weights_dir / "ablation" / f"afanet-{variant}.pt"),
            device,
            fpn_weights=_repository_weights(weights_dir / FIRST_FPN),
        )
        predictor.settings = dataclasses.replace(
            predictor.settings,
            edge_threshold=FIRST_INFERENCE["edge_threshold"],
            max_degree=FIRST_INFERENCE["max_degree"],
        )
        return predictor

    return load


def _baseline(method: str):
    def load(weights_dir: Path, device):
        from csboundary.models.baselines import baseline_module

        return baseline_module(method).Model.load(
            _repository_weights(weights_dir / "baselines" / f"{method}.pt"), device
        )

    return load


METHODS = [
    Method(
        "OrientationRefine",
        "orientation-refine",
        "segmentation",
        _baseline("orientation-refine"),
        ["baselines/orientation-refine-train.log"],
    ),
    # Sat2Graph's vertices and iCurb's segmentation input come from csBoundary's FPN: its training counts too
    Method(
        "Sat2Graph",
        "sat2graph",
        "graph generation",
        _baseline("sat2graph"),
        ["start-fpn-train.log", "start-surface-train.log", "fpn-train.log", "baselines/sat2graph-train.log"],
    ),
    Method(
        "Enhanced-iCurb",
        "icurb",
        "iterative",
        _baseline("icurb"),
        ["start-fpn-train.log", "start-surface-train.log", "fpn-train.log", "baselines/icurb-train.log"],
    ),
    Method(
        "csBoundary",
        "csboundary",
        "graph generation (ours)",
        _csboundary,
        [
            "start-fpn-train.log",
            "start-surface-train.log",
            "fpn-train.log",
            "surface-negatives-train.log",
            "afanet-train.log",
        ],
    ),
    Method(
        "csBoundary (ablation budget)",
        "ablation-full",
        "ablation",
        _ablation("ablation-full"),
        ["ablation/fpn-first-train.log", "ablation/afanet-ablation-full-train.log"],
        "ablation",
    ),
    Method(
        "csBoundary w/o global feature",
        "no-global",
        "ablation",
        _ablation("no-global"),
        ["ablation/fpn-first-train.log", "ablation/afanet-no-global-train.log"],
        "ablation",
    ),
    Method(
        "csBoundary w/o local feature",
        "no-local",
        "ablation",
        _ablation("no-local"),
        ["ablation/fpn-first-train.log", "ablation/afanet-no-local-train.log"],
        "ablation",
    ),
]


def training_time(log: Path) -> dict | None:
    """Seconds, steps and seconds per epoch of one training run, from its JSON-lines log."""
    if not log.exists():
        return None
    records = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    start = next((r for r in records if r.get("event") == "start"), None)
    done = next((r for r in reversed(records) if r.get("event") == "done"), None)
    if start is None or done is None:
        return None
    seconds = (datetime.fromisoformat(done["time"]) - datetime.fromisoformat(start["time"])).total_seconds()
    config = start["config"]
    steps = done["step"] - start["step"]
    return {"seconds": seconds, "steps": steps, "seconds_per_epoch": seconds / max(steps, 1) * steps_per_epoch(config)}


def training_area_px(config: dict) -> float:
    """Pixels of training imagery a run's config names: its train city and its ``worlds``."""
    area = 0.0
    city = config.get("train_city")
    if city:
        area += (city["tiles"][0] * city["tile_size"]) * (city["tiles"][1] * city["tile_size"])
    if config.get("worlds"):
        from csboundary.models.training.data import WorldsConfig

        worlds = WorldsConfig.from_dict(config["worlds"])
        area += worlds.cities * worlds.tiles[0] * worlds.tiles[1] * worlds.tile_size**2
    return area


def steps_per_epoch(config: dict) -> float:
    """Training steps that see the training imagery's area once (see the module docstring)."""
    area = training_area_px(config)
    if config["model"] == "afanet":
        return area / config["window"] ** 2
    options = config.get("options", {})
    if config["model"] == "icurb":  # a batch of ROIs drawn from the DAgger buffer
        return area / (options.get("batch", 64) * options.get("roi", 64) ** 2)
    return area / (config["batch"] * config["crop"] ** 2)


def unknown_methods(methods) -> list[str]:
    """The names in ``methods`` that are no method's key, sorted."""
    return sorted(set(methods or []) - {m.key for m in METHODS})


def benchmark_to_folder(
    out: Path,
    city_dir: Path | None = None,
    weights_dir: Path | None = None,
    device=None,
    methods=None,
    seed: int = 0,
    progress: bool = True,
    command: str = "",
) -> dict:
    """``csboundary benchmark``: :func:`run_benchmark` on ``city_dir`` (default: the test-split
    city seed 1, 1x1 tile of 5000 px, built on first use under data/cities) with the weights in
    ``weights_dir`` (default: the shipped ones), plus OUT/benchmark.json recording the
    ``command``, code version, city, weights and every score; returns the results."""
    import sys

    import torch

    from csboundary.models.checkpoint import code_version, shipped_weights
    from csboundary.models.training.data import CitySpec

    if unknown_methods(methods):
        raise ValueError(f"unknown method(s) {', '.join(unknown_methods(methods))}")
    city_dir = Path(city_dir or CitySpec("test", 1, (1, 1), 5000).ensure("data/cities"))
    weights_dir = Path(weights_dir or shipped_weights().parent)
    version = code_version()  # before the run: its own tables, tracked in docs/benchmark/, would mark the tree dirty
    results = run_benchmark(city_dir, out, weights_dir, device or torch.device("cpu"), methods, seed, progress=progress)
    record = {
        "command": command or "csboundary " + " ".join(sys.argv[1:]),
        "code_version": version,
        "city": str(city_dir),
        "weights": str(weights_dir),
        "results": {
            k: {
                "method": r["method"].name,
                **(
                    {"missing": r["missing"]}
                    if "missing" in r
                    else {
                        "scores": {s: v["metrics"] for s, v in r["scores"].items()},
                        "training": r["training"],
                        "inference_seconds": r["summary"]["seconds"],
                    }
                ),
            }
            for k, r in results.items()
        },
    }
    with atomic_path(out / "benchmark.json") as tmp:
        tmp.write_text(json.dumps(record, indent=1, default=float) + "\n")
    return results


def run_benchmark(
    city_dir: Path, out: Path, weights_dir: Path, device, methods=None, seed: int = 0, progress: bool = True
) -> dict:
    """Predict ``city_dir`` with every method, score it, write the tables; returns the results."""
    from csboundary.data import city_layout
    from csboundary.data.ground_truth import read_ground_truth
    from csboundary.data.raster import Mosaic
    from csboundary.pipeline.jobs.prediction_run import run_prediction
    from csboundary.pipeline.prediction.city_scores import evaluate_run

    chosen = [m for m in METHODS if methods is None or m.key in methods]
    results: dict[str, dict] = {}
    with Mosaic.open(city_layout.tiles_dir(city_dir)) as mosaic:
        lines = list(read_ground_truth(city_layout.ground_truth_path(city_dir), mosaic.crs).geometry)
        for method in chosen:
            try:
                model = method.loader(weights_dir, device)
            except Exception as exc:  # noqa: BLE001 - a missing or broken weights file is a row note, not a crash
                results[method.key] = {"method": method, "missing": f"{type(exc).__name__}: {exc}".splitlines()[0]}
                continue
            result, summary = run_prediction(
                mosaic,
                model,
                out / "predictions" / method.key,
                PredictionOptions(progress=progress),
                settings={"method": method.name},
                ground_truth=lines,
            )
            results[method.key] = {
                "method": method,
                "scores": evaluate_run(result, lines, seed),
                "summary": summary,
                "graph": result.graph,
                "training": [training_time(weights_dir / log) for log in method.logs],
            }
        write_figure(mosaic, lines, results, out / "fig7-comparison.png")
    write_tables(results, out, city_dir)
    return results


def write_tables(results: dict, out: Path, city_dir: Path) -> None:
    """tables.md plus one CSV per table (I patch scale, II city scale, III time, IV ablation)."""
    done = {k: r for k, r in results.items() if "scores" in r}
    rows = {"I": [], "II": [], "III": [], "IV": []}
    for r in done.values():
        m = r["method"]
        for table, scale in (("I", "patch"), ("II", "city")):
            if m.table == "comparison":
                rows[table].append([m.name, *(r["scores"][scale]["metrics"][k] for k in TABLE_METRICS)])
        if m.table == "ablation":
            rows["IV"].append([m.name, *(r["scores"]["city"]["metrics"][k] for k in TABLE_METRICS)])
        if m.table == "comparison":
            times = r["training"]
            train_epoch = sum(t["seconds_per_epoch"] for t in times) if all(times) else None
            train_total = sum(t["seconds"] for t in times) if all(times) else None
            s = r["summary"]
            rows["III"].append(
                [m.name, train_epoch, train_total, s["seconds"]["total"] / s["patches"], s["seconds"]["total"]]
            )
    header = ["method", *TABLE_METRICS]
    specs = {
        "I": ("Table I: patch scale (each patch's own graph on its core, averaged)", header),
        "II": ("Table II: city scale (the stitched graph)", header),
        "III": (
            "Table III: time (2 CPU cores)",
            ["method", "train s/epoch", "train s total", "inference s/patch", "inference s/city"],
        ),
        "IV": ("Table IV: ablation, city scale", header),
    }
    md = [
        f"# Comparison on `{city_dir}`",
        "",
        "Made by `csboundary benchmark` (command and versions in `benchmark.json`).",
        "",
    ]
    for table, (title, head) in specs.items():
        with atomic_path(out / f"table{table}.csv") as tmp, open(tmp, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(head)
            writer.writerows([[_cell(v, raw=True) for v in row] for row in rows[table]])
        md += [f"## {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        md += ["| " + " | ".join(_cell(v) for v in row) + " |" for row in rows[table]]
        md.append("")
    missing = [f"- {r['method'].name}: {r['missing']}" for r in results.values() if "missing" in r]
    if missing:
        md += ["Not run (no weights):", *missing, ""]
    with atomic_path(out / "tables.md") as tmp:
        tmp.write_text("\n".join(md))


def _cell(value, raw: bool = False) -> str:
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return "" if raw else "n/a"
    if isinstance(value, float):
        return f"{value:.6g}" if raw else (f"{value:.3f}" if value < 10 else f"{value:.0f}")
    return str(value)


def write_figure(mosaic, lines, results: dict, path: Path, panel: int = 500) -> None:
    """Fig. 7: one window (the core holding the most ground truth), a panel per method."""
    import cv2

    from csboundary.data.grid import PatchGrid
    from csboundary.graph import BoundaryGraph
    from csboundary.viz.overlay import render_window, write_png

    grid = PatchGrid.for_mosaic(mosaic)
    gt = BoundaryGraph.from_world_lines(lines, mosaic.transform)
    length: dict[tuple[int, int], float] = {}
    for k, edge_length in enumerate(gt.edge_lengths()):
        col, row = gt.vertices[gt.edges[k]].mean(axis=0)
        index = (int(row // grid.config.core), int(col // grid.config.core))
        length[index] = length.get(index, 0.0) + float(edge_length)
    window = grid.patch(*max(length, key=length.get, default=(0, 0))).core
    panels = [("ground truth", render_window(mosaic, window, lines, max_size=panel))]
    for r in results.values():
        if "graph" in r:
            predicted = r["graph"].to_linestrings(world=True)
            panels.append(
                (
                    r["method"].name,
                    render_window(mosaic, window, [], max_size=panel, layers=[(predicted, (255, 140, 0))]),
                )
            )
    cols = min(4, len(panels))
    rows = -(-len(panels) // cols)
    h, w = panels[0][1].shape[:2]
    canvas = np.full((rows * (h + 28), cols * w, 3), 255, np.uint8)
    for i, (name, image) in enumerate(panels):
        r, c = divmod(i, cols)
        canvas[r * (h + 28) + 28 : r * (h + 28) + 28 + h, c * w : c * w + w] = image[:h, :w]
        cv2.putText(
            canvas, name, (c * w + 6, r * (h + 28) + 20), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1, cv2.LINE_AA
        )
    write_png(path, canvas)
