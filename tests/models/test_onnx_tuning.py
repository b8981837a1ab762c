"""Choosing ONNX Runtime's graph optimisation level per network: the choice rule, the record
beside the exports (read back, not timed again; a damaged one replaced) and the timing loop."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("onnxruntime")

from csboundary.models import onnx_tuning  # noqa: E402
from csboundary.models.onnx_engine import OnnxNetworks  # noqa: E402
from csboundary.models.onnx_session import LEVELS  # noqa: E402
from csboundary.models.onnx_tuning import fastest_level, machine_key, tuned_levels  # noqa: E402


def test_the_fastest_level_wins_and_a_tie_keeps_the_default():
    assert fastest_level({"all": 0.41, "extended": 0.29}) == "extended"
    assert fastest_level({"all": 0.024, "extended": 0.033}) == "all"
    assert fastest_level({"all": 0.3, "extended": 0.3}) == LEVELS[0] == "all"
    assert fastest_level({"extended": 0.3}) == "extended"  # a level not timed never wins


def test_a_recorded_choice_is_used_without_timing(tmp_path, monkeypatch):
    networks = OnnxNetworks(b"not a model", b"not a model either", threads=2)
    path = tmp_path / "tuning.json"
    path.write_text(
        json.dumps(
            {
                machine_key(2): {"levels": {"fpn": "all", "afanet": "extended"}},
                machine_key(3): {"levels": {"fpn": "extended", "afanet": "extended"}},
            }
        )
    )
    monkeypatch.setattr(onnx_tuning, "time_levels", lambda *a, **k: pytest.fail("timed although recorded"))
    assert tuned_levels(path, networks.models, networks.thread_count) == {"fpn": "all", "afanet": "extended"}


@pytest.mark.parametrize("content", ["{not json", '["a list"]', None, "{}"])
def test_a_missing_or_damaged_record_is_timed_and_written(tmp_path, monkeypatch, capsys, content):
    networks = OnnxNetworks(b"fpn", b"afanet", threads=2)
    path = tmp_path / "tuning.json"
    if content is not None:
        path.write_text(content)
    times = {b"fpn": {"all": 0.4, "extended": 0.3}, b"afanet": {"all": 0.02, "extended": 0.03}}
    calls = []
    monkeypatch.setattr(
        onnx_tuning, "time_levels", lambda model, name, threads: calls.append((name, threads)) or times[model]
    )
    assert tuned_levels(path, networks.models, networks.thread_count) == {"fpn": "extended", "afanet": "all"}
    assert sorted(calls) == [("afanet", 2), ("fpn", 2)]
    assert "timing ONNX Runtime's optimisation levels for fpn, afanet on this machine (once)" in capsys.readouterr().err
    record = json.loads(path.read_text())
    assert record[machine_key(2)]["levels"] == {"fpn": "extended", "afanet": "all"}
    assert record[machine_key(2)]["seconds"]["fpn"] == {"all": 0.4, "extended": 0.3}
    # read back the second time, not timed again
    monkeypatch.setattr(onnx_tuning, "time_levels", lambda *a, **k: pytest.fail("timed again"))
    assert tuned_levels(path, networks.models, networks.thread_count) == {"fpn": "extended", "afanet": "all"}
    assert capsys.readouterr().err == ""  # read back silently


def test_another_machine_keeps_its_own_entry(tmp_path, monkeypatch):
    path = tmp_path / "tuning.json"
    other = {"levels": {"fpn": "all", "afanet": "all"}, "seconds": {}}
    path.write_text(json.dumps({"another CPU | onnxruntime 0.1 | 64 threads": other}))
    monkeypatch.setattr(onnx_tuning, "time_levels", lambda model, name, threads: {"all": 2.0, "extended": 1.0})
    assert tuned_levels(path, OnnxNetworks(b"f", b"a", threads=1).models, 1) == {
        "fpn": "extended",
        "afanet": "extended",
    }
    record = json.loads(path.read_text())
    assert record["another CPU | onnxruntime 0.1 | 64 threads"] == other and machine_key(1) in record


def test_a_network_not_recorded_yet_is_timed_alone_and_added_to_the_entry(tmp_path, monkeypatch):
    # the int8 FPN is asked for after the float networks were timed: only it is timed
    networks = OnnxNetworks(b"fpn", b"afanet", threads=2, fpn_int8_model=b"int8")
    path = tmp_path / "tuning.json"
    path.write_text(
        json.dumps(
            {
                machine_key(2): {
                    "levels": {"fpn": "extended", "afanet": "all"},
                    "seconds": {"fpn": {"all": 0.4, "extended": 0.3}},
                }
            }
        )
    )
    calls = []
    monkeypatch.setattr(
        onnx_tuning, "time_levels", lambda model, name, threads: calls.append(name) or {"all": 0.1, "extended": 0.2}
    )
    assert tuned_levels(path, networks.models, 2) == {"fpn": "extended", "afanet": "all", "fpn-int8": "all"}
    assert calls == ["fpn-int8"]
    entry = json.loads(path.read_text())[machine_key(2)]
    assert entry["levels"] == {"fpn": "extended", "afanet": "all", "fpn-int8": "all"}
    assert entry["seconds"]["fpn"] == {"all": 0.4, "extended": 0.3} and entry["seconds"]["fpn-int8"] == {
        "all": 0.1,
        "extended": 0.2,
    }
    # a level that is not one of LEVELS counts as not recorded
    path.write_text(json.dumps({machine_key(2): {"levels": {"fpn": "fastest", "afanet": "all", "fpn-int8": "all"}}}))
    calls.clear()
    assert tuned_levels(path, networks.models, 2)["fpn"] == "all" and calls == ["fpn"]


def test_time_levels_alternates_the_levels_and_keeps_each_ones_fastest_run(monkeypatch):
    runs = []

    class Session:
        def __init__(self, level):
            self.level = level

        def get_inputs(self):
            return []

        def run(self, outputs, inputs):
            runs.append(self.level)

    monkeypatch.setattr(onnx_tuning, "open_session", lambda model, threads, level, name: Session(level))
    ticks = iter([0.0, 5.0, 0.0, 1.0, 0.0, 2.0, 0.0, 7.0])  # all 5, extended 1, all 2, extended 7
    best = onnx_tuning.time_levels(b"m", "afanet", 2, runs=2, clock=lambda: next(ticks))
    assert best == {"all": 2.0, "extended": 1.0}
    assert runs == ["all", "extended"] + ["all", "extended"] * 2  # one warm-up each, then in turn


def test_example_inputs_follow_the_session_with_one_window_and_the_tuning_vertex_count():
    from types import SimpleNamespace

    session = SimpleNamespace(
        get_inputs=lambda: [
            SimpleNamespace(name="image", shape=["batch", 4, 1100, 1100]),
            SimpleNamespace(name="rois", shape=["m", 6, 64, 64]),
        ]
    )
    inputs = onnx_tuning.example_inputs(session)
    assert inputs["image"].shape == (1, 4, 1100, 1100) and inputs["rois"].shape == (
        onnx_tuning.TUNING_VERTICES,
        6,
        64,
        64,
    )
    assert all(v.dtype == "float32" and 0 <= v.min() and v.max() < 1 for v in inputs.values())


def test_an_instance_moved_to_another_machine_uses_that_machines_levels(tmp_path, monkeypatch):
    # as on a Dask worker: the instance is unpickled where another CPU or thread count runs it
    import pickle

    path = tmp_path / "tuning.json"
    path.write_text(
        json.dumps(
            {
                machine_key(2): {"levels": {"fpn": "extended", "afanet": "all"}},
                machine_key(1): {"levels": {"fpn": "all", "afanet": "extended"}},
            }
        )
    )
    networks = OnnxNetworks(b"fpn", b"afanet", threads=2)
    networks.tuning_path, networks.tuned_for = path, machine_key(2)
    networks.levels = tuned_levels(path, networks.models, 2)
    opened = []
    monkeypatch.setattr(onnx_tuning, "time_levels", lambda *a, **k: pytest.fail("timed although recorded"))
    monkeypatch.setattr(
        "csboundary.models.onnx_engine.open_session",
        lambda model, threads, level, name: opened.append((name, threads, level)),
    )
    moved = pickle.loads(pickle.dumps(networks))
    moved.threads = 1
    moved._session("fpn")
    moved._session("afanet")
    assert opened == [("fpn", 1, "all"), ("afanet", 1, "extended")] and moved.tuned_for == machine_key(1)
    networks._session("fpn")  # where it was tuned: its own levels, nothing looked up again
    assert opened[-1] == ("fpn", 2, "extended")


def test_a_timing_that_cannot_be_recorded_is_still_used(tmp_path, monkeypatch):
    path = tmp_path / "not-a-folder"
    path.write_text("")
    monkeypatch.setattr(onnx_tuning, "time_levels", lambda model, name, threads: {"all": 2.0, "extended": 1.0})
    assert tuned_levels(path / "tuning.json", {"fpn": b"f"}, 1) == {"fpn": "extended"}
