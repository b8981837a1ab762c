"""The edge confidence end to end: a bundle's confidence becomes every output's score,
``--min-confidence`` keeps exactly the edges at or above it, ``evaluate`` reports how well it
separates true from false edges, and ``fit-confidence`` writes a bundle that ``predict`` uses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyogrio
import pytest

from csboundary.graph import BoundaryGraph
from helpers import run_cli

pytest.importorskip("sklearn")
FEATURES_USED = ("boundary_mean", "surface_contrast", "log_length", "kind_corner")


@pytest.fixture(scope="module")
def confident_bundle(tmp_path_factory) -> Path:
    """The shipped networks with a small confidence fitted on made-up evidence: enough to check
    the plumbing (the shipped confidence is judged in docs/confidence.md, not here)."""
    from csboundary.graph.edge_evidence import FEATURES
    from csboundary.models.checkpoint import load_checkpoint, save_checkpoint, shipped_weights
    from csboundary.models.confidence_model import fit_edge_confidence

    rng = np.random.default_rng(0)
    evidence = rng.uniform(0, 1, (600, len(FEATURES)))
    positive = rng.uniform(0, 1, 600) < evidence[:, FEATURES.index("boundary_mean")]
    model = fit_edge_confidence(evidence, positive, np.arange(600) % 3, FEATURES_USED, n_trees=10, depth=2)
    payload = {k: v for k, v in load_checkpoint(shipped_weights(), ("bundle",)).items() if k not in ("format", "kind")}
    payload["confidence"] = model.to_dict()
    return save_checkpoint(tmp_path_factory.mktemp("confident") / "confident.pt", "bundle", **payload)


@pytest.fixture(scope="module")
def predictions(demo_run, confident_bundle, tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("confidence-runs")
    out = {}
    for name, extra in (("all", ()), ("sure", ("--min-confidence", "0.6"))):
        out[name] = root / name
        # the default engine: the bundle's networks are the shipped ones, whose ONNX exports the
        # run's cache holds (it is keyed by the networks, not the file)
        done = run_cli(
            "predict",
            str(demo_run / "city"),
            "--out",
            str(out[name]),
            "--weights",
            str(confident_bundle),
            *extra,
            "--device",
            "cpu",
            "--quiet",
        )
        assert done.returncode == 0, done.stderr
    return out


def test_every_output_carries_the_confidence(predictions):
    graph = BoundaryGraph.read_json(predictions["all"] / "graph.json")
    scores = np.asarray(graph.edge_scores, float)
    assert ((scores >= 0) & (scores <= 1)).all()
    edges = pyogrio.read_dataframe(predictions["all"] / "boundaries.gpkg", layer="edges")
    np.testing.assert_allclose(edges["confidence"].to_numpy(), scores)
    boundaries = pyogrio.read_dataframe(predictions["all"] / "boundaries.gpkg", layer="road_boundaries")
    for _, row in boundaries.iterrows():
        mine = edges[edges["boundary_id"] == row["boundary_id"]]
        assert row["confidence_mean"] == pytest.approx(np.average(mine["confidence"], weights=mine["length_m"]))


def test_min_confidence_keeps_exactly_the_edges_at_or_above_it(predictions):
    scores = np.asarray(BoundaryGraph.read_json(predictions["all"] / "graph.json").edge_scores, float)
    sure = np.asarray(BoundaryGraph.read_json(predictions["sure"] / "graph.json").edge_scores, float)
    assert 0 < len(sure) < len(scores)
    assert len(sure) == int((scores >= 0.6).sum())
    np.testing.assert_allclose(np.sort(sure), np.sort(scores[scores >= 0.6]))


def test_evaluate_reports_the_confidence(predictions, demo_run, tmp_path):
    done = run_cli(
        "evaluate", str(predictions["all"] / "graph.json"), str(demo_run / "city"), "--json", str(tmp_path / "s.json")
    )
    assert done.returncode == 0, done.stderr
    assert "confidence:" in done.stdout and "AUC" in done.stdout
    report = json.loads((tmp_path / "s.json").read_text())["confidence"]
    assert 0 <= report["auc"] <= 1 and 0 <= report["ece"] <= 1
    assert set(report["review"]) == {"0.1", "0.2", "0.5"}


def test_min_confidence_needs_a_bundle_with_a_confidence(demo_run, tmp_path):
    from csboundary.models.checkpoint import load_checkpoint, save_checkpoint, shipped_weights

    payload = {
        k: v
        for k, v in load_checkpoint(shipped_weights(), ("bundle",)).items()
        if k not in ("format", "kind", "confidence")
    }
    plain = save_checkpoint(tmp_path / "plain.pt", "bundle", **payload)
    done = run_cli(
        "predict",
        str(demo_run / "city"),
        "--out",
        str(tmp_path / "out"),
        "--weights",
        str(plain),
        "--min-confidence",
        "0.5",
        "--device",
        "cpu",
        "--quiet",
    )
    assert done.returncode != 0
    assert done.stderr.strip().startswith("error: --min-confidence") and "Traceback" not in done.stderr
    assert not (tmp_path / "out" / "graph.json").exists()


def synth_cities(folder: Path, tile_size: int) -> list[Path]:
    """Two small validation-split cities (seeds 1 and 2) made by the command line."""
    cities = []
    for seed in (1, 2):
        city = folder / f"city{seed}"
        done = run_cli(
            "synth", str(city), "--seed", str(seed), "--tile-size", str(tile_size), "--split", "valid", "--quiet"
        )
        assert done.returncode == 0, done.stderr
        cities.append(city)
    return cities


def test_fit_confidence_writes_a_bundle_predict_uses(tmp_path):
    from csboundary.models.checkpoint import file_sha256, load_checkpoint

    cities = synth_cities(tmp_path, 1100)
    out = tmp_path / "fitted.pt"
    done = run_cli("fit-confidence", *map(str, cities), "--out", str(out), "--trees", "5", "--device", "cpu", "--quiet")
    assert done.returncode == 0, done.stderr
    table = load_checkpoint(out, ("bundle",))["confidence"]
    recorded = table["provenance"]["cities"]
    assert [c["ground_truth_sha256"] for c in recorded] == [file_sha256(c / "ground_truth.gpkg") for c in cities]
    assert table["provenance"]["n_trees"] == 5 and len(table["tree_starts"]) == 6
    image = next((cities[0] / "tiles").glob("*.tif"))
    done = run_cli(
        "predict-patch",
        str(image),
        "--out",
        str(tmp_path / "patch"),
        "--weights",
        str(out),
        "--device",
        "cpu",
        "--engine",
        "torch",
    )
    assert done.returncode == 0, done.stderr
    scores = np.asarray(BoundaryGraph.read_json(tmp_path / "patch" / "graph.json").edge_scores, float)
    assert len(scores) and ((scores >= 0) & (scores <= 1)).all()


def test_fit_confidence_on_cities_without_ground_truth_is_one_line(tmp_path):
    import geopandas as gpd

    from csboundary.data.ground_truth import LAYER

    cities = synth_cities(tmp_path, 700)
    for city in cities:
        truth = city / "ground_truth.gpkg"
        empty = gpd.read_file(truth, layer=LAYER).iloc[:0]
        truth.unlink()
        empty.to_file(truth, layer=LAYER, driver="GPKG")
    for given, needle in ((cities[:1], "needs at least two"), (cities, "no predicted edge lies on the ground truth")):
        done = run_cli(
            "fit-confidence",
            *map(str, given),
            "--out",
            str(tmp_path / "fitted.pt"),
            "--trees",
            "5",
            "--device",
            "cpu",
            "--engine",
            "torch",
            "--quiet",
        )  # an error path: no ONNX export to wait for
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and needle in lines[0] and str(cities[0]) in lines[0], (
            done.stderr
        )
        assert not (tmp_path / "fitted.pt").exists()
