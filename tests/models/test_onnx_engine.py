"""The ONNX Runtime engine: the same probabilities as PyTorch on a real patch, cached exports,
and a clear refusal where it cannot run."""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("onnxruntime")

from csboundary.errors import InputError  # noqa: E402
from csboundary.models.afanet import adjacency_from_logits  # noqa: E402
from csboundary.models.onnx_engine import OnnxNetworks  # noqa: E402
from csboundary.models.onnx_session import LEVELS  # noqa: E402
from csboundary.pipeline.prediction.patch import PatchPredictor  # noqa: E402
from helpers import run_cli  # noqa: E402


@pytest.fixture(scope="module")
def patch_image(tmp_path_factory):
    """A real 1100 x 1100 window: the centre patch of a synthetic test city, shipped model's pixel size."""
    from csboundary.data.grid import PatchGrid
    from csboundary.data.raster import Mosaic

    city = tmp_path_factory.mktemp("onnx") / "city"
    done = run_cli(
        "synth", str(city), "--tiles", "1x1", "--tile-size", "2400", "--seed", "5", "--split", "test", "--quiet"
    )
    assert done.returncode == 0, done.stderr
    with Mosaic.open(city / "tiles") as mosaic:
        return mosaic.read(PatchGrid.for_mosaic(mosaic).patch(1, 1).expanded).data


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """This module's own export cache: its int8 FPN is calibrated on fewer windows (a faster
    test) and must not reach the run's shared cache (conftest.onnx_cache)."""
    from csboundary.models.onnx_session import CACHE_ENV

    folder = tmp_path_factory.mktemp("onnx-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(CACHE_ENV, str(folder))
        yield folder


@pytest.fixture(scope="module")
def predictors(tmp_path_factory, cache):
    import shutil

    from csboundary.models.checkpoint import shipped_weights

    weights = tmp_path_factory.mktemp("w") / "bundle.pt"
    shutil.copy(shipped_weights(), weights)
    torch_engine = PatchPredictor.load(weights, torch.device("cpu"))
    onnx_engine = PatchPredictor.load(weights, torch.device("cpu"))
    assert onnx_engine.use_engine("onnx", weights) == "onnx" and torch_engine.use_engine("torch", weights) == "torch"
    assert len(list(cache.glob("*.onnx"))) == 2
    assert set(onnx_engine.onnx.levels) == {"fpn", "afanet"}  # timed on this machine and recorded beside the exports
    assert len(list(cache.glob("*-tuning-*.json"))) == 1
    assert not (weights.parent / ".onnx-cache").exists() and sorted(p.name for p in weights.parent.iterdir()) == [
        "bundle.pt"
    ]
    return torch_engine, onnx_engine, weights


@pytest.mark.parametrize("level", LEVELS)
def test_onnx_probabilities_equal_pytorch_on_a_real_patch(patch_image, predictors, level):
    """At each graph optimisation level the tuning may pick (onnx_tuning)."""
    torch_engine, onnx_engine, _ = predictors
    onnx_engine.onnx = OnnxNetworks(
        onnx_engine.onnx.fpn_model, onnx_engine.onnx.afanet_model, levels={"fpn": level, "afanet": level}
    )
    maps_torch = torch_engine.patch_maps([None], [patch_image])[0]
    maps_onnx = onnx_engine.patch_maps([None], [patch_image])[0]
    assert maps_torch.shape == (
        3,
        1100,
        1100,
    )  # keypoint, boundary and (the shipped surface check reads it) road surface
    assert np.abs(maps_onnx - maps_torch).max() < 1e-5

    found = torch_engine.extract(maps_torch)
    assert found.n_vertices >= 20  # a patch with boundaries, so AfANet has work
    tensor = torch.cat([torch.from_numpy(patch_image / 255.0).float(), torch.from_numpy(maps_torch[:2])], 0)
    vertices = torch.from_numpy(found.vertices.astype(np.float32))
    p_torch = torch_engine.afanet.adjacency(tensor, vertices).numpy()
    views = [view.numpy() for view in torch_engine.afanet.views(tensor, vertices)]
    p_onnx = adjacency_from_logits(torch.from_numpy(onnx_engine.onnx.afanet_logits(*views))).numpy()
    assert np.abs(p_onnx - p_torch).max() < 1e-5
    assert torch_engine.afanet.training is False  # exporting left the PyTorch networks as they were
    assert set(onnx_engine.onnx._sessions) == {"fpn", "afanet"}  # both ran on ONNX Runtime


def test_bfloat16_runs_the_fpn_in_pytorch_whatever_the_engine(patch_image, predictors):
    import warnings

    from csboundary.models.batchnorm_folding import fold_batch_norms
    from csboundary.models.maps import predict_probabilities

    _, onnx_engine, _ = predictors
    full = onnx_engine.patch_maps([None], [patch_image])[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a CPU without bfloat16 units is warned about, not refused
        onnx_engine.use_precision("bfloat16")
    try:
        half = onnx_engine.patch_maps([None], [patch_image])[0]
    finally:
        onnx_engine.use_precision("float32")
    assert onnx_engine.folded_fpn is None
    expected = predict_probabilities(
        fold_batch_norms(onnx_engine.fpn), patch_image[None], torch.device("cpu"), "bfloat16"
    )[0][: len(half)]
    assert np.array_equal(
        half, expected
    )  # PyTorch's bfloat16 maps (batch norms folded), not ONNX Runtime's float32 ones
    assert 0 < np.abs(half - full).max() < 0.5


def test_the_export_is_reused_by_the_same_networks_in_another_file(predictors, cache, tmp_path):
    """Keyed by the networks, not the file: the same file again, and a copy elsewhere with
    trailing bytes (torch ignores them; the file's hash changes), export and time nothing.
    A changed tensor gets its own export: tests/models/test_onnx_cache.py."""
    import shutil

    _, _, weights = predictors
    stamps = {p.name: p.stat().st_mtime_ns for p in cache.glob("*")}
    again = PatchPredictor.load(weights, torch.device("cpu"))
    again.use_engine("onnx", weights)
    assert {p.name: p.stat().st_mtime_ns for p in cache.glob("*")} == stamps  # not exported or timed again
    other = tmp_path / "elsewhere" / "other.pt"
    other.parent.mkdir()
    shutil.copy(weights, other)
    with open(other, "ab") as f:
        f.write(b"\0")
    moved = PatchPredictor.load(other, torch.device("cpu"))
    moved.use_engine("auto", other)
    assert moved.engine == "onnx" and {p.name: p.stat().st_mtime_ns for p in cache.glob("*")} == stamps
    assert moved.onnx.fpn_model == again.onnx.fpn_model and list(other.parent.iterdir()) == [other]


def test_the_onnx_engine_is_refused_off_the_cpu_and_unknown_engines(predictors):
    torch_engine, _, weights = predictors
    with pytest.raises(InputError, match="unknown engine"):
        torch_engine.use_engine("tensorrt", weights)
    torch_engine.device = torch.device("cuda")
    try:
        with pytest.raises(InputError, match="runs on the CPU"):
            torch_engine.use_engine("onnx", weights)
        assert torch_engine.use_engine("auto", weights) == "torch"
    finally:
        torch_engine.device = torch.device("cpu")


def test_int8_runs_the_quantized_fpn_near_the_float_one(patch_image, predictors, cache, monkeypatch):
    import onnx

    from csboundary.models import onnx_quantization

    monkeypatch.setattr(onnx_quantization, "CALIBRATION_STYLES", ("classic", "downtown"))  # two windows: a faster test
    _, onnx_engine, weights = predictors
    floats = onnx_engine.patch_maps([None], [patch_image])[0]
    onnx_engine.use_precision("int8")
    try:
        assert onnx_engine.use_engine("onnx", weights) == "onnx"
        quantized = onnx_engine.patch_maps([None], [patch_image])[0]
        networks = onnx_engine.onnx
    finally:
        onnx_engine.use_precision("float32")
        onnx_engine.use_engine("onnx", weights)
    assert quantized.shape == floats.shape and quantized.dtype == np.float32
    error = np.abs(quantized - floats)
    assert 0 < error.max() < 0.6 and error.mean() < 0.01  # near, not the float network run again
    assert set(networks._sessions) == {"fpn-int8"} and set(networks.levels) == {"fpn", "afanet", "fpn-int8"}
    graph = onnx.load_from_string(networks.fpn_int8_model).graph
    int8_weights = [t for t in graph.initializer if t.data_type == onnx.TensorProto.INT8 and len(t.dims) == 4]
    assert len(int8_weights) == sum(n.op_type == "Conv" for n in onnx.load_from_string(networks.fpn_model).graph.node)
    assert len(networks.fpn_int8_model) < 0.5 * len(networks.fpn_model)
    from csboundary.models.onnx_engine import EXPORT_VERSION
    from csboundary.models.onnx_quantization import QUANTIZATION_VERSION

    made = list(cache.glob("*-fpn-int8-*.onnx"))  # cached, versioned with the quantization
    assert [p.name.endswith(f"-fpn-int8-v{EXPORT_VERSION}q{QUANTIZATION_VERSION}.onnx") for p in made] == [True]
    assert onnx_engine.onnx.fpn_int8_model is None  # float32 again: the float export only


def test_auto_precision_runs_whichever_fpn_was_timed_faster_here_and_says_why(predictors, monkeypatch):
    from csboundary.models import onnx_quantization
    from csboundary.pipeline.prediction.patch import faster_fpn

    monkeypatch.setattr(onnx_quantization, "CALIBRATION_STYLES", ("classic",))  # a faster test
    torch_engine, onnx_engine, weights = predictors
    onnx_engine.use_precision("auto")
    try:
        assert onnx_engine.precision == "auto"  # resolved by the engine
        onnx_engine.use_engine("onnx", weights)
        seconds = (
            onnx_engine.onnx.fpn_seconds()
        )  # both FPNs timed at their levels on this machine, read back from the record
        assert set(seconds) == {"fpn", "fpn-int8", "afanet"} and all(v > 0 for v in seconds.values())
        faster = "int8" if seconds["fpn-int8"] < seconds["fpn"] else "float32"
        assert onnx_engine.precision == faster and onnx_engine.precision_choice.startswith(f"{faster}: its FPN ran in")
    finally:
        onnx_engine.use_precision("float32")
        onnx_engine.use_engine("onnx", weights)
    torch_engine.use_precision("auto")
    try:
        torch_engine.use_engine("torch", weights)
        assert torch_engine.precision == "float32" and "torch engine" in torch_engine.precision_choice
    finally:
        torch_engine.use_precision("float32")
    assert faster_fpn({"fpn": 0.40, "fpn-int8": 0.15})[0] == "int8"
    assert faster_fpn({"fpn": 0.15, "fpn-int8": 0.40}) == (
        "float32",
        "float32: its FPN ran in 150 ms against 400 ms in int8 on this CPU",
    )
    assert faster_fpn({"fpn": 0.15})[0] == "float32"  # not timed in int8: float32


def test_the_int8_fpn_leaves_a_core_to_the_rest_of_the_pipeline(predictors, monkeypatch):
    """int8 makes the FPN cost what the rest of a patch costs: the networks take one thread fewer
    than the process has, never fewer than one; float32 keeps them all."""
    _, onnx_engine, weights = predictors
    networks = OnnxNetworks(b"", b"", threads=3)
    assert networks.thread_count == 3
    networks.spare_a_core()
    assert networks.thread_count == 2
    assert OnnxNetworks(b"", b"", threads=1).thread_count == 1
    lone = OnnxNetworks(b"", b"", threads=1)
    lone.spare_a_core()
    assert lone.thread_count == 1
    opened = OnnxNetworks(b"", b"", threads=2)
    opened._sessions["fpn"] = object()
    with pytest.raises(RuntimeError, match="after a session was opened"):
        opened.spare_a_core()

    monkeypatch.setattr(torch, "get_num_threads", lambda: 4)
    assert onnx_engine.onnx.spare_core is False and onnx_engine.onnx.thread_count == 4  # float32: every core
    onnx_engine.use_precision("int8")
    try:
        onnx_engine.use_engine("onnx", weights)
        assert onnx_engine.onnx.spare_core is True and onnx_engine.onnx.thread_count == 3
    finally:
        onnx_engine.use_precision("float32")
        onnx_engine.use_engine("onnx", weights)
    assert onnx_engine.onnx.spare_core is False


def test_int8_is_refused_where_onnx_runtime_does_not_run_it(predictors, patch_image):
    import warnings

    torch_engine, _, weights = predictors
    torch_engine.use_precision("int8")
    try:
        with pytest.raises(InputError, match="int8 runs the FPN on ONNX Runtime: use --engine onnx"):
            torch_engine.use_engine("torch", weights)
        # an image smaller than the export's window runs in float32 PyTorch, and says so
        torch_engine.onnx = OnnxNetworks(b"", b"")
        with pytest.warns(
            UserWarning, match="int8 FPN is made for 1100 px windows: this 600 x 600 px image runs in float32"
        ):
            small = torch_engine.patch_maps([None], [patch_image[:, :600, :600]])[0]
    finally:
        torch_engine.onnx = None
        torch_engine.use_precision("float32")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.array_equal(small, torch_engine.patch_maps([None], [patch_image[:, :600, :600]])[0])
    torch_engine.device = torch.device("cuda")
    try:
        with pytest.raises(InputError, match="int8 runs the FPN on ONNX Runtime on the CPU"):
            torch_engine.use_precision("int8")
    finally:
        torch_engine.device = torch.device("cpu")


def test_the_command_line_refuses_int8_on_the_torch_engine(tmp_path):
    done = run_cli("demo", "--out", str(tmp_path / "demo"), "--engine", "torch", "--precision", "int8")
    assert done.returncode == 2 and "error: --precision: int8 runs the FPN on ONNX Runtime" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "demo" / "prediction").exists()


def test_the_int8_fpn_is_asked_for_only_once_it_is_made():
    with pytest.raises(ValueError, match="no int8 FPN"):
        OnnxNetworks(b"fpn", b"afanet").fpn_logits(None, int8=True)
