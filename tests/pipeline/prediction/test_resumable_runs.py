"""Resumable and distributed city runs: a run killed at any moment (SIGKILL included) and run
again continues where it stopped and writes the same graph.json; a changed input or setting is
refused; a Dask cluster of two worker processes writes the same graph.json as one process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from csboundary.graph import BoundaryGraph
from csboundary.graph.graph_arrays import graph_arrays, graph_from_arrays
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.run_store import STORE_DIR, RunMismatch, RunStore
from helpers import run_cli

COMMON = (
    "--device",
    "cpu",
    "--quiet",
    "--threads",
    "1",
)  # one torch thread: the FPN's numbers match a 1-thread worker's


@pytest.fixture(scope="module")
def city(tmp_path_factory):
    """2200 x 2200 px at the shipped model's 0.152 m: 3 x 3 patches, real boundaries found."""
    path = tmp_path_factory.mktemp("resume") / "city"
    done = run_cli(
        "synth", str(path), "--tiles", "2x2", "--tile-size", "1100", "--seed", "3", "--split", "test", "--quiet"
    )
    assert done.returncode == 0, done.stderr
    return path


@pytest.fixture(scope="module")
def reference(city, tmp_path_factory):
    out = tmp_path_factory.mktemp("reference") / "pred"
    done = run_cli("predict", str(city), "--out", str(out), *COMMON, timeout=600)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["patches"] == 9 and summary["counts"]["edges"] > 20  # a graph worth comparing
    assert summary["work"] == {"patches_predicted": 9, "windows_connected": 9, "patches_reused": 0, "windows_reused": 0}
    assert not (out / STORE_DIR).exists()  # the work store goes once the outputs are in place
    return out


def _graphs(out: Path) -> list[str]:
    folder = out / STORE_DIR / "graphs"
    return (
        [p.name for p in folder.iterdir() if p.suffix == ".npz" and not p.name.startswith(".")]
        if folder.exists()
        else []
    )


def killed_run(city: Path, out: Path, windows: int = 3) -> None:
    """``predict`` killed with SIGKILL once ``windows`` windows have their graphs stored."""
    job = subprocess.Popen(
        [sys.executable, "-m", "csboundary", "predict", str(city), "--out", str(out), *COMMON],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 300
    while len(_graphs(out)) < windows:
        assert job.poll() is None and time.time() < deadline, "the run ended before it could be killed"
        time.sleep(0.05)
    os.kill(job.pid, signal.SIGKILL)
    job.wait()


def test_a_run_killed_with_sigkill_resumes_to_the_same_graph(city, reference, tmp_path):
    out = tmp_path / "pred"
    killed_run(city, out)
    assert not (out / "graph.json").exists() and not (out / "summary.json").exists()
    done_before = len(_graphs(out))

    again = run_cli("predict", str(city), "--out", str(out), *COMMON, timeout=600)
    assert again.returncode == 0, again.stderr
    work = json.loads((out / "summary.json").read_text())["work"]
    assert work["windows_reused"] >= done_before >= 3 and work["windows_connected"] == 9 - work["windows_reused"]
    assert work["patches_predicted"] + work["patches_reused"] == 9  # no patch predicted twice by the second run
    assert (out / "graph.json").read_bytes() == (reference / "graph.json").read_bytes()
    assert not (out / STORE_DIR).exists()


def test_a_changed_setting_or_input_is_refused_and_restart_discards(city, tmp_path):
    out = tmp_path / "pred"
    store = RunStore.open(out / STORE_DIR, {"inputs": [], "settings": {"edge_threshold": 0.9}})
    store.save_maps((0, 0), np.zeros((2, 1100, 1100), np.float32))
    refused = run_cli("predict", str(city), "--out", str(out), *COMMON)
    lines = [line for line in refused.stderr.strip().splitlines() if line.startswith("error")]
    assert refused.returncode == 2 and len(lines) == 1, refused.stderr
    assert "unfinished run with other inputs" in lines[0] and "--restart" in lines[0], refused.stderr
    assert (out / STORE_DIR / "maps" / "0_0.npy").exists()  # nothing discarded without being asked
    done = run_cli("predict", str(city), "--out", str(out), "--restart", *COMMON, timeout=600)
    assert done.returncode == 0, done.stderr


def test_damaged_store_entries_are_computed_again(city, reference, tmp_path):
    out = tmp_path / "pred"
    killed_run(city, out, windows=2)
    store = out / STORE_DIR
    maps = sorted(p for p in (store / "maps").iterdir() if p.suffix == ".npy" and not p.name.startswith("."))
    graph = sorted(p for p in (store / "graphs").iterdir() if p.suffix == ".npz" and not p.name.startswith("."))[0]
    with open(maps[-1], "r+b") as f:  # a maps file cut short, as a full disk or a crash leaves it
        f.truncate(maps[-1].stat().st_size // 2)
    graph.write_text("not a graph")
    again = run_cli("predict", str(city), "--out", str(out), *COMMON, timeout=600)
    assert again.returncode == 0, again.stderr
    warned = [line for line in again.stderr.splitlines() if "damaged in the run store" in line]
    assert len(warned) == 2 and all(line.startswith("warning: ") for line in warned), again.stderr
    assert (out / "graph.json").read_bytes() == (reference / "graph.json").read_bytes()


def test_a_flipped_byte_is_found_by_its_checksum(tmp_path):
    manifest = {"inputs": [], "settings": {}}
    store = RunStore.open(tmp_path / "s", manifest)
    store.save_maps((0, 0), np.full((2, 50, 50), 0.25, np.float32))
    store.save_maps((0, 1), np.full((2, 50, 50), 0.5, np.float32))
    path = tmp_path / "s" / "maps" / "0_1.npy"
    raw = bytearray(path.read_bytes())
    raw[-1] ^= 0x40  # same size, a readable array, one value wrong
    path.write_bytes(bytes(raw))
    with pytest.warns(UserWarning, match="0_1.npy: damaged"):
        again = RunStore.open(tmp_path / "s", manifest)
    assert again.maps_done() == {(0, 0)}
    assert float(again.load_maps((0, 0)).max()) == 0.25


def test_a_damaged_manifest_is_one_line_with_the_way_out(tmp_path):
    RunStore.open(tmp_path / "out" / "s", {"inputs": [], "settings": {}})
    (tmp_path / "out" / "s" / "manifest.json").write_text("{trunc")
    with pytest.raises(RunMismatch, match="damaged.*--restart"):
        RunStore.open(tmp_path / "out" / "s", {"inputs": [], "settings": {}})


def test_a_run_that_did_no_work_blocks_nothing(tmp_path):
    RunStore.open(
        tmp_path / "s", {"inputs": [["a.tif", 10, 1]], "settings": {}}
    )  # e.g. the input was damaged: nothing stored
    with pytest.warns(UserWarning, match="had done no work"):
        store = RunStore.open(tmp_path / "s", {"inputs": [["a.tif", 11, 2]], "settings": {}})  # the input fixed
    assert json.loads((store.root / "manifest.json").read_text())["inputs"] == [["a.tif", 11, 2]]


def test_the_manifest_names_what_differs(tmp_path):
    RunStore.open(tmp_path / "s", {"inputs": [["a.tif", 10, 1]], "settings": {"w": "x"}}).save_maps((0, 0), None)
    with pytest.raises(RunMismatch, match="other inputs"):
        RunStore.open(tmp_path / "s", {"inputs": [["a.tif", 11, 1]], "settings": {"w": "x"}})
    with pytest.raises(RunMismatch, match="other settings"):
        RunStore.open(tmp_path / "s", {"inputs": [["a.tif", 10, 1]], "settings": {"w": "y"}})
    assert RunStore.open(tmp_path / "s", {"inputs": [["a.tif", 10, 1]], "settings": {"w": "x"}}).root == tmp_path / "s"


def test_a_graph_survives_the_store_exactly(tmp_path):
    rng = np.random.default_rng(0)
    graph = BoundaryGraph(
        rng.random((5, 2)) * 1000,
        [[0, 1], [1, 2], [3, 4]],
        vertex_kinds=["isolated", "end", "end", "isolated", "isolated"],
        edge_kinds=["normal", "corner", "normal"],
        edge_polylines=[None, rng.random((7, 2)), None],
        edge_scores=rng.random(3),
        crs="EPSG:32618",
    )
    store = RunStore(tmp_path / "s")
    store.save_graph((2, 5), graph)
    back = store.load_graph((2, 5))
    assert store.graphs_done() == {(2, 5)}
    assert np.array_equal(back.vertices, graph.vertices) and np.array_equal(back.edges, graph.edges)
    assert back.vertex_kinds == graph.vertex_kinds and back.edge_kinds == graph.edge_kinds and back.crs == graph.crs
    assert back.edge_polylines[0] is None and np.array_equal(back.edge_polylines[1], graph.edge_polylines[1])
    assert np.array_equal(back.edge_scores, graph.edge_scores)
    empty = graph_from_arrays(graph_arrays(BoundaryGraph()))
    assert empty.n_vertices == 0 and empty.n_edges == 0


def test_two_dask_workers_write_the_local_graph(city, reference, tmp_path):
    pytest.importorskip("distributed")
    import torch
    from distributed import Client, LocalCluster

    from csboundary.data.raster import Mosaic
    from csboundary.models.checkpoint import file_sha256, shipped_weights
    from csboundary.pipeline.jobs.prediction_run import run_prediction
    from csboundary.pipeline.prediction.distributed import dask_executor
    from csboundary.pipeline.prediction.patch import PatchPredictor

    predictor = PatchPredictor.load(None, torch.device("cpu"))
    # the precision the command line chose for the reference on this machine (--precision auto), and its engine:
    # both travel to the workers
    predictor.use_precision(
        json.loads((reference / "summary.json").read_text())["settings"].get("precision", "float32")
    )
    predictor.use_engine("auto")
    out = tmp_path / "pred"
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40
        ) as cluster,
        Client(cluster) as client,
        Mosaic.open(city / "tiles") as mosaic,
    ):
        settings = {"weights_sha256": file_sha256(shipped_weights())}
        _, summary = run_prediction(
            mosaic,
            predictor,
            out,
            PredictionOptions(progress=False, threads=1),
            settings=settings,
            executor=dask_executor(client),
        )
        assert len(client.nthreads()) == 2
    assert summary["work"]["windows_connected"] == 9
    assert (out / "graph.json").read_bytes() == (reference / "graph.json").read_bytes()


def test_maps_written_behind_are_readable_at_once_and_dropped_for_good(tmp_path):
    store = RunStore(tmp_path / "s", write_behind=True)
    maps = {(0, k): np.full((2, 8, 8), k / 10, np.float32) for k in range(12)}  # more than the writer may queue
    for index, m in maps.items():
        store.save_maps(index, m)
        assert np.array_equal(store.load_maps(index), m.astype(np.float16))  # served before its file is in place
    store.drop_maps((0, 3))
    store.flush()
    assert store.maps_done() == set(maps) - {(0, 3)}
    assert not (tmp_path / "s" / "maps" / "0_3.npy").exists()
    fresh = RunStore(tmp_path / "s")  # what the next process finds
    assert np.array_equal(fresh.load_maps((0, 11)), maps[(0, 11)].astype(np.float16))
    assert fresh.held_map_bytes() == 11 * (2 * 8 * 8 * 2 + 128)  # float16 arrays with their .npy headers
