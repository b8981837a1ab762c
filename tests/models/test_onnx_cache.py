"""The ONNX export cache: in the user's cache folder (or ``$CSBOUNDARY_CACHE``), keyed by the
networks' content, so a copy of a weights file elsewhere, or one saved again with other
provenance, reuses the export, and a changed tensor does not."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from csboundary.errors import InputError
from csboundary.models import onnx_engine, onnx_tuning
from csboundary.models.checkpoint import load_afanet, load_checkpoint, load_fpn, shipped_weights
from csboundary.models.onnx_engine import cache_dir, network_key
from csboundary.models.onnx_session import CACHE_ENV, cache_folder


@pytest.fixture(scope="module")
def payload():
    return load_checkpoint(shipped_weights(), ("bundle",))


def resaved(payload: dict, path, **changes):
    """The shipped bundle written again to ``path``, with ``changes`` to its entries."""
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({**payload, **changes}, path)
    return path


def changed_tensor(payload: dict) -> dict:
    """The FPN's tensors with one value of one weight moved."""
    state = dict(payload["fpn"])
    name = next(k for k, v in state.items() if v.is_floating_point() and v.dim() == 4)
    state[name] = state[name].clone(memory_format=torch.contiguous_format)
    state[name].view(-1)[0] += 1e-3
    return state


def key_of(path) -> str:
    bundle = load_checkpoint(path, ("bundle",))
    return network_key(load_fpn(bundle), load_afanet(bundle))


def test_the_key_is_the_networks_not_the_file_its_place_or_its_provenance(payload, tmp_path):
    shipped = key_of(shipped_weights())
    copy = resaved(payload, tmp_path / "a" / "copy.pt")
    other = resaved(
        payload,
        tmp_path / "b" / "renamed.pt",
        provenance={"note": "saved again"},
        code_version="9.9.9+other",
        inference={**payload["inference"], "note": "other metadata"},
    )
    assert copy.read_bytes() != other.read_bytes()  # other files...
    assert key_of(copy) == key_of(other) == shipped  # ...the same networks
    assert key_of(resaved(payload, tmp_path / "c" / "copy.pt", fpn=changed_tensor(payload))) != shipped
    fpn, afanet = load_fpn(payload), load_afanet(payload)
    assert network_key(fpn.to(memory_format=torch.contiguous_format), afanet) == shipped  # the values, not their layout
    fpn.config = dataclasses.replace(
        fpn.config, encoder_scale=fpn.config.encoder_scale / 2
    )  # same tensors, another network
    assert network_key(fpn, afanet) != shipped


def test_a_copy_elsewhere_reuses_the_export_and_a_changed_tensor_gets_its_own(payload, tmp_path, monkeypatch):
    from csboundary.pipeline.prediction.patch import PatchPredictor

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    exported = []

    def fake(name):
        return lambda network: exported.append(name) or f"<{name} model {len(exported)}>".encode()

    monkeypatch.setattr(onnx_engine, "export_fpn", fake("fpn"))
    monkeypatch.setattr(onnx_engine, "export_afanet", fake("afanet"))
    monkeypatch.setattr(onnx_tuning, "time_levels", lambda model, name, threads: {"all": 1.0, "extended": 2.0})

    def engine(path):
        predictor = PatchPredictor.load(path, torch.device("cpu"))
        assert predictor.use_engine("onnx", path) == "onnx"
        return predictor.onnx

    first = engine(resaved(payload, tmp_path / "a" / "bundle.pt"))
    assert exported == ["fpn", "afanet"]
    made = sorted(p.name for p in (tmp_path / "cache").iterdir())
    assert len(made) == 3 and all(name.startswith(made[0][:16]) for name in made)  # fpn, afanet, tuning: one key
    again = engine(resaved(payload, tmp_path / "b" / "moved.pt", provenance={"note": "copied"}))
    assert exported == ["fpn", "afanet"]  # nothing exported again
    assert again.models == first.models and again.tuning_path == first.tuning_path
    engine(resaved(payload, tmp_path / "c" / "bundle.pt", fpn=changed_tensor(payload)))
    assert exported == ["fpn", "afanet"] * 2
    names = sorted(p.name for p in (tmp_path / "cache").iterdir())
    assert len(names) == 6 and len({name[:16] for name in names}) == 2  # written whole: no temporaries left
    assert not any((tmp_path / folder / ".onnx-cache").exists() for folder in "abc")  # nothing beside the weights


def test_the_cache_folder_is_the_users_or_the_one_set(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "set"))
    assert cache_dir() == tmp_path / "set" and (tmp_path / "set").is_dir()
    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_folder() == tmp_path / "xdg" / "csboundary" / "onnx"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_folder() == tmp_path / "home" / ".cache" / "csboundary" / "onnx"


def test_a_cache_folder_that_cannot_be_written_is_one_line(tmp_path, monkeypatch):
    (tmp_path / "a-file").write_text("")
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "a-file"))
    with pytest.raises(InputError) as caught:
        cache_dir()
    message = str(caught.value)
    assert message.startswith(f"{tmp_path / 'a-file'}: cannot hold the cached ONNX exports") and "\n" not in message
    assert f"set {CACHE_ENV} to a writable folder or use --engine torch" in message


def test_a_damaged_export_names_the_cache_folder(tmp_path, monkeypatch):
    pytest.importorskip("onnxruntime")
    from csboundary.models.onnx_session import open_session

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    with pytest.raises(InputError, match=f"delete the cached exports in {tmp_path / 'cache'}"):
        open_session(b"not a model", 1, "all", "fpn")


def test_a_second_exporter_waits_for_the_first(tmp_path):
    """Two processes (or Dask workers) that start at once on a new machine export a network once:
    the second waits on the export lock, then finds the file made."""
    import threading
    import time

    from csboundary.models.onnx_engine import exporting

    path = tmp_path / "k-fpn-v3.onnx"
    order = []

    def first():
        with exporting(path):
            order.append("first in")
            time.sleep(0.5)
            path.write_bytes(b"made")
            order.append("first out")

    worker = threading.Thread(target=first)
    worker.start()
    while not order:
        time.sleep(0.01)
    with exporting(path):  # flock: each open of the lock file is its own lock, threads of one process included
        order.append("second in")
        assert path.read_bytes() == b"made"
    worker.join()
    assert order == ["first in", "first out", "second in"]


def test_an_unwritable_cache_runs_auto_in_torch_with_a_warning(tmp_path, monkeypatch):
    """A read-only home (the cache cannot be made) is no reason to stop a prediction that
    --engine auto can run in torch; --engine onnx stops with the cache's one line."""
    from csboundary.errors import InputError, InputWarning
    from csboundary.models.onnx_session import CACHE_ENV
    from csboundary.pipeline.prediction.patch import load_predictor

    (tmp_path / "file").write_text("not a folder")
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "file"))
    with pytest.warns(InputWarning, match="running the networks in torch"):
        predictor = load_predictor(None, "cpu", engine="auto")
    assert predictor.engine == "torch"
    with pytest.raises(InputError, match="cannot hold the cached ONNX exports"):
        load_predictor(None, "cpu", engine="onnx")


def test_a_bad_input_is_never_taken_for_a_full_disk(tmp_path, monkeypatch):
    """With almost no space free, a write that failed on a bug or a bad input keeps its own error."""
    import shutil
    from collections import namedtuple

    from csboundary.data.atomic import is_disk_full
    from csboundary.errors import InputError

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda folder: usage(10**9, 10**9 - 10, 10))
    assert not is_disk_full(InputError("x.gpkg", "not a GeoPackage"), tmp_path)
    assert not is_disk_full(TypeError("bad argument"), tmp_path)
    assert is_disk_full(RuntimeError("Failed to commit transaction"), tmp_path)  # GDAL's words for a full disk
