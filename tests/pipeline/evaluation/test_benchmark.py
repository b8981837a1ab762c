"""The comparison benchmark: tables from tiny weights on a tiny city; training time from logs."""

from __future__ import annotations

import csv
import json

import pytest
import torch

from csboundary.data.synth.city import synthesize_city
from csboundary.data.synth.config import SynthConfig
from csboundary.models.afanet import AfANet, AfANetConfig
from csboundary.models.baselines.orientation_refine import KIND, Options, _Pair
from csboundary.models.checkpoint import save_checkpoint
from csboundary.models.fpn import FPN, FPNConfig
from csboundary.pipeline.evaluation.benchmark import run_benchmark, steps_per_epoch, training_time

TINY = {"widths": [8, 8, 8, 8], "blocks": [1, 1, 1, 1], "pyramid": 8, "stem": 8}


def _log(path, start, end, steps, config):
    path.write_text(
        "\n".join(
            json.dumps(r)
            for r in [
                {"time": start, "event": "start", "step": 0, "config": config},
                {"time": end, "event": "done", "step": steps},
            ]
        )
        + "\n"
    )


def test_training_time_per_epoch_from_a_log(tmp_path):
    city = {"tiles": [2, 2], "tile_size": 5000}
    config = {"model": "sat2graph", "train_city": city, "batch": 4, "crop": 250, "window": 1100}
    _log(tmp_path / "a.log", "2026-01-01T10:00:00", "2026-01-01T10:10:00", 1000, config)
    t = training_time(tmp_path / "a.log")
    assert t["seconds"] == 600 and t["steps"] == 1000
    assert steps_per_epoch(config) == 1e8 / 250000  # 400 steps of 4 x 250^2 px
    assert t["seconds_per_epoch"] == pytest.approx(0.6 * 400)
    assert steps_per_epoch({**config, "model": "afanet"}) == pytest.approx(1e8 / 1100**2)
    assert training_time(tmp_path / "missing.log") is None
    worlds = {**config, "train_city": None, "worlds": {"cities": 16, "tiles": [1, 1], "tile_size": 2500}}
    assert steps_per_epoch(worlds) == 16 * 2500**2 / 250000  # 16 cities of 2500^2 px


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    torch.manual_seed(0)
    root = tmp_path_factory.mktemp("weights")
    fpn_config = FPNConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in TINY.items()})
    fpn = FPN(fpn_config)
    with torch.no_grad():
        fpn.head[-1].bias.fill_(-3.0)
    afanet_config = AfANetConfig(global_size=64, roi=16, encoder_widths=(8, 8), dim=32, layers=1)
    save_checkpoint(
        root / "csboundary-synthetic.pt",
        "bundle",
        fpn=fpn.state_dict(),
        fpn_config=fpn_config.to_dict(),
        afanet=AfANet(afanet_config).state_dict(),
        afanet_config=afanet_config.to_dict(),
        inference={"edge_threshold": 0.5, "max_degree": 2},
    )
    pair = _Pair(Options(refiner=TINY), FPNConfig.from_dict({**TINY, "out_channels": 17}))
    (root / "baselines").mkdir()
    save_checkpoint(
        root / "baselines" / f"{KIND}.pt", KIND, **{KIND: pair.state_dict(), f"{KIND}_config": pair.config.to_dict()}
    )
    config = {"model": KIND, "train_city": {"tiles": [1, 1], "tile_size": 1000}, "batch": 2, "crop": 100}
    _log(root / "baselines" / f"{KIND}-train.log", "2026-01-01T10:00:00", "2026-01-01T10:01:40", 100, config)
    return root


def test_benchmark_writes_every_table_and_the_figure(weights, tmp_path):
    city = tmp_path / "city"
    synthesize_city(city, 1, "test", (1, 2), SynthConfig(tile_size=600, gsd=0.3), progress=False)
    out = tmp_path / "bench"
    results = run_benchmark(
        city,
        out,
        weights,
        torch.device("cpu"),
        ["csboundary", "orientation-refine", "icurb", "no-global"],
        progress=False,
    )
    assert "scores" in results["csboundary"] and "scores" in results["orientation-refine"]
    assert "missing" in results["icurb"] and "missing" in results["no-global"]  # no weights: reported, not guessed
    table1 = list(csv.reader(open(out / "tableI.csv")))
    assert [row[0] for row in table1[1:]] == ["OrientationRefine", "csBoundary"]
    table3 = list(csv.reader(open(out / "tableIII.csv")))
    assert table3[0][:3] == ["method", "train s/epoch", "train s total"]
    rows = {row[0]: row for row in table3[1:]}
    assert float(rows["OrientationRefine"][2]) == 100  # 100 s from its log; epoch = 1e6 / (2 * 100^2) = 50 steps
    assert float(rows["OrientationRefine"][1]) == pytest.approx(50.0)
    assert rows["csBoundary"][1] == ""  # no logs beside these weights
    md = (out / "tables.md").read_text()
    assert "Table I" in md and "Table IV" in md and "Enhanced-iCurb" in md
    assert (out / "fig7-comparison.png").stat().st_size > 0
    assert (out / "predictions" / "csboundary" / "boundaries.gpkg").exists()

    # Table II reports the scores of the prediction it wrote: re-scored here from graph.json and
    # the city's ground truth, independently of the benchmark's own bookkeeping
    from csboundary.data import city_layout
    from csboundary.data.ground_truth import read_ground_truth
    from csboundary.data.raster import Mosaic
    from csboundary.graph import BoundaryGraph
    from csboundary.metrics import evaluate
    from csboundary.pipeline.evaluation.benchmark import TABLE_METRICS

    predicted = BoundaryGraph.read_json(out / "predictions" / "csboundary" / "graph.json")
    with Mosaic.open(city_layout.tiles_dir(city)) as mosaic:
        gt = BoundaryGraph.from_world_lines(
            list(read_ground_truth(city_layout.ground_truth_path(city), mosaic.crs).geometry), mosaic.transform
        )
        again = evaluate(predicted, gt, scale="city", seed=0, extent=(0, 0, mosaic.width, mosaic.height))["metrics"]
    table2 = {row[0]: row[1:] for row in list(csv.reader(open(out / "tableII.csv")))[1:]}
    reported = dict(zip(TABLE_METRICS, map(float, table2["csBoundary"])))
    assert reported == pytest.approx({k: again[k] for k in TABLE_METRICS}, abs=2e-3)
    assert 0 <= reported["precision@5"] <= 1 and 0 <= reported["apls"] <= 1


def test_benchmark_json_records_the_code_version_from_before_the_run(tmp_path, monkeypatch):
    # The run rewrites docs/benchmark/, which git tracks: a version read afterwards would always
    # say ".dirty". Here the version "changes" once the run has started.
    import csboundary.models.checkpoint as checkpoint
    import csboundary.pipeline.evaluation.benchmark as benchmark

    state = {"running": False}
    monkeypatch.setattr(checkpoint, "code_version", lambda: "0.1.0+abc.dirty" if state["running"] else "0.1.0+abc")

    def fake_run(*args, **kwargs):
        state["running"] = True
        return {}

    monkeypatch.setattr(benchmark, "run_benchmark", fake_run)
    benchmark.benchmark_to_folder(tmp_path, city_dir=tmp_path, weights_dir=tmp_path, progress=False)
    assert json.loads((tmp_path / "benchmark.json").read_text())["code_version"] == "0.1.0+abc"
