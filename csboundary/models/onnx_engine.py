"""The networks on ONNX Runtime: the same weights, 2-3x faster on a CPU than eager PyTorch.

PyTorch stays the engine for training and for CUDA; on a CPU, ``predict`` exports the FPN and
AfANet to ONNX on first use and runs them with ONNX Runtime's CPU provider when the optional
``onnxruntime`` package is installed (``pip install 'csboundary[onnx]'``). The exported files are
cached in the user's cache folder (``$CSBOUNDARY_CACHE``, else ``$XDG_CACHE_HOME/csboundary/onnx``,
else ``~/.cache/csboundary/onnx``: :func:`cache_dir`), keyed by the networks themselves
(:func:`network_key`): a copy of a weights file in another folder, or a bundle saved again with
other provenance, reuses the export; a changed tensor or config gets a new one.

The FPN is exported for the city grid's 1100 x 1100 windows (any batch); other sizes
(``PatchPredictor.maps`` on an image of its own) run in PyTorch. AfANet is exported from its
views on (the resized tensor, the windows around the vertices, cut by PyTorch) for any number of
vertices (at least two; fewer need no network). Both return logits; the probabilities are taken as in PyTorch.
A session is not picklable: an :class:`OnnxNetworks` sent to a Dask worker carries the model
bytes and opens its sessions there on first use.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import sys
import warnings
from pathlib import Path
from typing import Iterator

import numpy as np
import torch

from csboundary.errors import InputError
from csboundary.models.onnx_session import CACHE_ENV, DEFAULT_LEVEL, WINDOW, cache_folder, open_session

OPSET = 17
EXPORT_VERSION = 3  # bump when the export changes, so cached files are made again (3: AfANet from its views)


def cache_dir() -> Path:
    """The folder of the cached exports (``onnx_session.cache_folder``), made if missing.

    One that cannot be made or written is one InputError naming it and ``CSBOUNDARY_CACHE``,
    not a fallback to a temporary folder: there every run would export and quantize again
    (about a minute, and 3 GB for the quantizer) with nothing but a warning to say why, and
    either leave some 35 MB behind or share a fixed folder under /tmp that other users could
    fill. The line tells what to set once (or ``--engine torch``, which needs no export)."""
    from csboundary.data.atomic import check_output_dir

    folder = cache_folder()
    try:
        return check_output_dir(folder, create=True)
    except InputError as exc:
        raise InputError(
            folder,
            f"cannot hold the cached ONNX exports ({exc.problem}); set {CACHE_ENV} to a writable folder "
            "or use --engine torch",
        ) from exc


@contextlib.contextmanager
def exporting(path: Path) -> Iterator[None]:
    """Hold the export lock of ``path`` (an OS lock on ``path.lock``, released however the
    process ends): the Dask workers or runs that start at once on a new machine export and
    quantize a network once (a minute and 3 GB each), not once each. Unlocked without ``fcntl``."""
    try:
        import fcntl
    except ImportError:  # Windows: each exports, the renames keep the files whole
        yield
        return
    lock = path.with_name(path.name + ".lock")
    with open(lock, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:  # gone before it is let go: a waiter holds it open, and whoever comes later finds the file made
            lock.unlink(missing_ok=True)
            fcntl.flock(handle, fcntl.LOCK_UN)


def network_key(fpn, afanet) -> str:
    """Hex SHA-256 of what the exports are made from: the opset, and for the FPN then AfANet
    the class, the config (JSON, sorted keys) and every state-dict entry in name order (name,
    dtype, shape and the bytes of the values in row-major order, whatever the memory format).
    Not the file: its path, provenance and metadata do not change the networks. The export and
    quantization versions are in each cached file's name (``<key[:16]>-fpn-v3.onnx``,
    ``-fpn-int8-v3q3.onnx``). 40-80 ms for the shipped bundle's 28.6 MB of tensors (2 shared cores)."""
    digest = hashlib.sha256(f"opset {OPSET}\n".encode())
    for name, network in (("fpn", fpn), ("afanet", afanet)):
        config = network.config.to_dict() if hasattr(network.config, "to_dict") else vars(network.config)
        digest.update(json.dumps([name, type(network).__name__, config], sort_keys=True, default=str).encode() + b"\n")
        for key, tensor in sorted(network.state_dict().items()):
            values = tensor.detach().cpu().contiguous()
            digest.update(f"{key} {values.dtype} {tuple(values.shape)}\n".encode())
            digest.update(values.reshape(-1).view(torch.uint8).numpy())
    return digest.hexdigest()


class _AfANetLogits(torch.nn.Module):
    """AfANet from its views (``AfANet.views``: resized tensor, vertex windows, normalised
    vertices) to logits, for M >= 2 vertices: the views stay in PyTorch."""

    def __init__(self, afanet):
        super().__init__()
        self.afanet = afanet

    def forward(self, small: torch.Tensor, rois: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
        return self.afanet.logits_from_views(small, rois, xy)


def _export(module: torch.nn.Module, args: tuple, names: tuple[list[str], list[str]], dynamic: dict) -> bytes:
    # eval, and the whole module tree: the exporter puts the module back in the mode it found it
    # in, and a wrapper left in training mode would switch the wrapped network's batch norms too
    module = module.cpu().eval()
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation and tracer warnings
        torch.onnx.export(
            module,
            args,
            buffer,
            dynamo=False,
            opset_version=OPSET,
            input_names=names[0],
            output_names=names[1],
            dynamic_axes=dynamic,
        )
    return buffer.getvalue()


def export_fpn(fpn) -> bytes:
    example = torch.rand(1, 4, WINDOW, WINDOW)
    return _export(fpn, (example,), (["image"], ["logits"]), {"image": {0: "batch"}, "logits": {0: "batch"}})


AFANET_INPUTS = ("small", "rois", "xy")


def export_afanet(afanet) -> bytes:
    with torch.no_grad():
        example = afanet.cpu().eval().views(torch.rand(6, WINDOW, WINDOW), torch.rand(8, 2) * WINDOW)
    return _export(
        _AfANetLogits(afanet),
        example,
        (list(AFANET_INPUTS), ["logits"]),
        {"rois": {0: "m"}, "xy": {0: "m"}, "logits": {0: "m", 1: "m"}},
    )


class OnnxNetworks:
    """The FPN and AfANet of one weights file on ONNX Runtime (CPU), and the FPN quantized to
    int8 when ``--precision int8`` asked for it (models/onnx_quantization.py)."""

    def __init__(
        self,
        fpn_model: bytes,
        afanet_model: bytes,
        threads: int | None = None,
        levels: dict[str, str] | None = None,
        fpn_int8_model: bytes | None = None,
    ):
        self.fpn_model, self.afanet_model, self.fpn_int8_model, self.threads = (
            fpn_model,
            afanet_model,
            fpn_int8_model,
            threads,
        )
        # leave one core to the rest of the pipeline (see spare_a_core)
        self.spare_core = False
        self.levels = dict(levels or {})  # graph optimisation level per network (see onnx_tuning)
        # where the levels were timed and for which machine key: a Dask worker on another CPU or
        # with another thread count looks its own up (or times them) when it opens a session
        self.tuning_path: Path | None = None
        self.tuned_for: str | None = None
        self._sessions: dict[str, object] = {}

    @property
    def models(self) -> dict[str, bytes]:
        """Each network's ONNX model by name: ``fpn``, ``afanet`` and, when made, ``fpn-int8``."""
        models = {"fpn": self.fpn_model, "afanet": self.afanet_model}
        if self.fpn_int8_model is not None:
            models["fpn-int8"] = self.fpn_int8_model
        return models

    @property
    def thread_count(self) -> int:
        """Threads per network: ``threads`` (default: torch's), one fewer with ``spare_core``."""
        threads = self.threads or torch.get_num_threads()
        return max(1, threads - 1) if self.spare_core else threads

    def spare_a_core(self) -> None:
        """Run the networks on one thread fewer than the process has cores for. The int8 FPN
        costs about what the rest of a patch's work costs (0.17-0.18 core-s each on the 64-patch
        seed-7 city), so the rest, on the thread that calls the networks, needs a core of its
        own: on 2 cores the city ran at 229.5 km2/h with the int8 FPN on both, 282.5-308.8 with
        it on one (docs/cpu-inference.md). Before the sessions are opened."""
        if self._sessions:
            raise RuntimeError("spare_a_core after a session was opened: its thread count is fixed")
        self.spare_core = True

    @classmethod
    def for_networks(cls, fpn, afanet, int8: bool = False) -> "OnnxNetworks":
        """The cached exports of ``fpn`` and ``afanet`` (:func:`network_key`, in :func:`cache_dir`),
        made first if missing (and the FPN quantized to int8 when ``int8``), with each network's
        graph optimisation level timed on this machine (once, cached beside them). Each file is
        written under a temporary name and renamed into place (data/atomic.py), so processes
        sharing the cache never read half a file, and made by one process while the others
        wait (:func:`exporting`)."""
        from csboundary.data.atomic import atomic_path
        from csboundary.models.onnx_quantization import QUANTIZATION_VERSION, quantize_fpn
        from csboundary.models.onnx_tuning import machine_key, tuned_levels

        folder, key = cache_dir(), network_key(fpn, afanet)[:16]

        def cached(name: str, make, version: str = f"v{EXPORT_VERSION}") -> bytes:
            path = folder / f"{key}-{name}-{version}.onnx"
            if not path.exists():
                with exporting(path):  # another process making this file: wait for it, then read it
                    if not path.exists():
                        print(
                            f"csboundary: preparing the {name} network for ONNX Runtime (once per network, cached in {folder})",
                            file=sys.stderr,
                            flush=True,
                        )
                        data = make()
                        with atomic_path(path) as tmp:
                            tmp.write_bytes(data)
            return path.read_bytes()

        fpn_model = cached("fpn", lambda: export_fpn(fpn))
        afanet_model = cached("afanet", lambda: export_afanet(afanet))
        int8_model = (
            cached("fpn-int8", lambda: quantize_fpn(fpn_model), f"v{EXPORT_VERSION}q{QUANTIZATION_VERSION}")
            if int8
            else None
        )
        # exporting moved the networks to the CPU and eval mode already; they stay usable in torch
        networks = cls(fpn_model, afanet_model, fpn_int8_model=int8_model)
        networks.tuning_path = folder / f"{key}-tuning-v{EXPORT_VERSION}.json"
        networks.levels = tuned_levels(networks.tuning_path, networks.models, networks.thread_count)
        networks.tuned_for = machine_key(networks.thread_count)
        return networks

    def fpn_seconds(self) -> dict[str, float]:
        """The fastest timed run of each network at its chosen level on this machine, from the
        tuning record (``fpn``, ``fpn-int8`` when made, ``afanet``)."""
        from csboundary.models.onnx_tuning import recorded_seconds

        if self.tuning_path is None:
            return {}
        return recorded_seconds(self.tuning_path, self.thread_count, self.levels)

    def _levels_here(self) -> None:
        """The levels for this process's machine and thread count, if they were tuned for others
        (an instance unpickled on a Dask worker): read from the tuning record, else timed here."""
        from csboundary.models.onnx_tuning import machine_key, tuned_levels

        if self.tuning_path is None or self.tuned_for is None:
            return
        key = machine_key(self.thread_count)
        if key != self.tuned_for:
            self.levels, self.tuned_for = tuned_levels(self.tuning_path, self.models, self.thread_count), key

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_sessions"] = {}
        return state

    def _session(self, name: str):
        session = self._sessions.get(name)
        if session is None:
            if not self._sessions:
                self._levels_here()
            model = self.models[name]
            session = open_session(model, self.thread_count, self.levels.get(name, DEFAULT_LEVEL), name)
            self._sessions[name] = session
        return session

    def fpn_logits(self, images: np.ndarray, int8: bool = False) -> np.ndarray:
        """(B, 4, 1100, 1100) float32 in [0, 1] -> (B, C, 1100, 1100) logits; ``int8``: from the
        quantized FPN (made by ``for_networks(int8=True)``)."""
        if int8 and self.fpn_int8_model is None:
            raise ValueError(
                "no int8 FPN: it is made by for_networks(int8=True) (PatchPredictor.use_precision('int8') before use_engine)"
            )
        return self._session("fpn-int8" if int8 else "fpn").run(
            None, {"image": np.ascontiguousarray(images, np.float32)}
        )[0]

    def afanet_logits(self, small: np.ndarray, rois: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """AfANet's views (``AfANet.views``) of M >= 2 vertices -> (M, M) logits."""
        session = self._session("afanet")
        views = dict(zip(AFANET_INPUTS, (small, rois, xy)))
        # a branch that is off (the ablations) leaves its view out of the exported graph
        return session.run(
            None, {i.name: np.ascontiguousarray(views[i.name], np.float32) for i in session.get_inputs()}
        )[0]
