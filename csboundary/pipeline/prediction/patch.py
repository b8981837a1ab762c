"""One patch, end to end: FPN maps -> vertices -> AfANet adjacency -> graph (paper Alg. 1 body).

The returned graph has the extracted vertices; its edges are the corner edges of gathered runs
(kind ``corner``, with the skeleton polyline, score = mean keypoint probability along it), the
AfANet edges (kind ``normal``, score = symmetric adjacency probability) and, when the fill is on,
the boundary both missed, from the segmentation skeleton (kind ``skeleton``, score = mean
boundary probability along it; graph/skeleton_fill.py); with an FPN that maps the road surface
and the surface check on, edges with no roadway beside them are then dropped
(graph/surface_check.py). With a bundle that has an edge confidence, the city graph's scores are
then replaced by it (pipeline/prediction/edge_scoring.py).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from csboundary.data.grid import Patch
from csboundary.data.units import MODEL_GSD
from csboundary.errors import InputError, InputWarning
from csboundary.graph import BoundaryGraph
from csboundary.graph.crossings import added_crossings
from csboundary.graph.edge_support import unsupported_pairs
from csboundary.graph.end_joining import join_ends
from csboundary.graph.outline_fusion import fused_with_outline
from csboundary.graph.settings import GraphOverrides, GraphSettings
from csboundary.graph.skeleton_fill import fill_from_skeleton
from csboundary.graph.surface_check import surface_checked
from csboundary.graph.surface_gate import gated_maps
from csboundary.graph.vertex_extraction import extract_vertices
from csboundary.models.afanet import AfANet, adjacency_from_logits
from csboundary.models.batchnorm_folding import fold_batch_norms
from csboundary.models.checkpoint import load_afanet, load_checkpoint, load_fpn, shipped_weights
from csboundary.models.confidence_model import EdgeConfidence
from csboundary.models.decoding import graph_from_adjacency
from csboundary.models.device import bfloat16_hardware, resolve_device
from csboundary.models.fpn import FPN, SURFACE
from csboundary.models.maps import PRECISIONS, bands_and_maps, predict_probabilities, unit_bands
from csboundary.models.onnx_engine import OnnxNetworks, cache_dir
from csboundary.models.onnx_session import WINDOW, onnxruntime_available


def export_cache_usable() -> bool:
    """Whether the ONNX export cache can be made and written; when not, ``--engine auto`` runs
    torch and says why in a warning (``--engine onnx`` stops with the cache's one line)."""
    try:
        cache_dir()
    except InputError as exc:
        warnings.warn(f"{exc}; running the networks in torch", InputWarning, stacklevel=3)
        return False
    return True


@dataclass
class PatchPredictor:
    """The trained networks as the city pipeline's :class:`~csboundary.models.patch_model.PatchModel`,
    with the graph settings of their bundle (``settings``, overridden from the command line by
    :meth:`override`)."""

    fpn: FPN
    afanet: AfANet
    device: torch.device
    settings: GraphSettings = field(default_factory=GraphSettings)
    pixel_size_m: float = MODEL_GSD  # the training imagery's pixel size: input is resampled to it
    onnx: OnnxNetworks | None = None  # the networks on ONNX Runtime (CPU), see use_engine
    precision: str = "float32"  # the FPN's arithmetic, see use_precision
    precision_choice: str | None = None  # how ``auto`` chose it, in words (None: asked for by name)
    folded_fpn: torch.nn.Module | None = field(
        default=None, repr=False
    )  # the FPN with batch norms folded, for bfloat16
    confidence: EdgeConfidence | None = (
        None  # the city graph's edge confidence (models/confidence_model.py; None: scores as found)
    )
    collect_evidence: bool = False  # keep the maps the edges' evidence is read from (to fit a confidence)

    def override(self, options: GraphOverrides) -> None:
        """The command line's graph options in place of the bundle's settings; a check that
        reads the road surface needs an FPN with a surface head, a confidence threshold a bundle
        with a confidence."""
        for name, value in (
            ("--surface-check", options.surface_check),
            ("--surface-gate", options.surface_gate),
            ("--roadway-outline", options.roadway_outline),
        ):
            if value is not None and value > 0 and not self.fpn.config.surface:
                raise InputError(name, "the FPN of these weights has no road-surface head")
        if options.min_confidence and self.confidence is None:
            raise InputError(
                "--min-confidence", "these weights have no edge confidence (csboundary fit-confidence adds one)"
            )
        self.settings = self.settings.overridden(options)

    @property
    def engine(self) -> str:
        return "onnx" if self.onnx is not None else "torch"

    def use_engine(self, engine: str, weights: str | Path | None = None, fpn_weights: str | Path | None = None) -> str:
        """``torch``, ``onnx`` (ONNX Runtime, CPU only) or ``auto`` (onnx on a CPU when
        onnxruntime is installed, and its export cache can be written: else torch, with a
        warning); returns the engine chosen. The export is cached by the networks' content
        (models/onnx_engine.py); ``weights`` and ``fpn_weights``, the files they came from, are
        kept for callers and decide nothing."""
        if engine not in ("auto", "torch", "onnx"):
            raise InputError("--engine", f"unknown engine {engine!r} (auto, torch or onnx)")
        on_cpu = self.device.type == "cpu"
        if engine == "onnx" and not on_cpu:
            raise InputError(
                "--engine", f"the onnx engine runs on the CPU, not {self.device}; use --device cpu or --engine torch"
            )
        if engine == "onnx" and not onnxruntime_available():
            raise InputError("--engine", "onnxruntime is not installed (pip install 'csboundary[onnx]')")
        if engine == "auto" and on_cpu and onnxruntime_available() and not export_cache_usable():
            engine = "torch"
        if engine == "torch" or (engine == "auto" and not (on_cpu and onnxruntime_available())):
            if self.precision == "int8":
                raise InputError(
                    "--precision",
                    "int8 runs the FPN on ONNX Runtime: use --engine onnx or auto "
                    "(on a CPU, with onnxruntime installed: pip install 'csboundary[onnx]')",
                )
            if self.precision == "auto":
                self.precision, self.precision_choice = "float32", "float32: the torch engine runs the FPN in float32"
            self.onnx = None
            return "torch"
        self.onnx = OnnxNetworks.for_networks(self.fpn, self.afanet, int8=self.precision in ("int8", "auto"))
        if self.precision == "auto":
            self.precision, self.precision_choice = faster_fpn(self.onnx.fpn_seconds())
        if self.precision == "int8":
            self.onnx.spare_a_core()
        return "onnx"

    def use_precision(self, precision: str) -> None:
        """``auto`` (int8 where this CPU runs the quantized FPN faster than the float32 one on
        ONNX Runtime, timed on first use; else float32: :func:`faster_fpn`), ``float32``,
        ``bfloat16`` (the FPN in PyTorch under bfloat16
        autocast, whatever the
        engine: ONNX Runtime has no bfloat16 convolutions on a CPU; AfANet stays float32 on the
        engine chosen) or ``int8`` (the FPN quantized on ONNX Runtime: made by ``use_engine``,
        which must come after, and which refuses the torch engine). Warns where the hardware has
        no bfloat16 units, as bfloat16 is slower there."""
        if precision not in PRECISIONS and precision != "auto":
            raise InputError("--precision", f"unknown precision {precision!r} (auto, float32, bfloat16 or int8)")
        self.precision_choice = precision if precision != "auto" else None
        if precision == "auto":  # resolved by use_engine, which must come after
            self.precision, self.folded_fpn = "auto", None
            return
        if precision == "int8" and self.device.type != "cpu":
            raise InputError(
                "--precision", f"int8 runs the FPN on ONNX Runtime on the CPU, not {self.device}; use --device cpu"
            )
        if precision == "bfloat16" and not bfloat16_hardware(self.device):
            if self.device.type == "cuda":
                raise InputError(
                    "--precision", f"{torch.cuda.get_device_name(self.device)} has no bfloat16 support; use float32"
                )
            warnings.warn(
                "this CPU has no bfloat16 units (AMX or AVX512-BF16): --precision bfloat16 will be slower than float32",
                InputWarning,
                stacklevel=2,
            )
        self.precision = precision
        self.folded_fpn = fold_batch_norms(self.fpn) if precision == "bfloat16" else None

    @classmethod
    def load(
        cls, weights: str | Path | None, device: torch.device, fpn_weights: str | Path | None = None
    ) -> "PatchPredictor":
        """From a bundle (both models; the shipped one by default), or an AfANet checkpoint plus
        ``fpn_weights``."""
        path = Path(weights) if weights else shipped_weights()
        payload = load_checkpoint(path, ("bundle", "afanet"), map_location=device)
        if payload["kind"] == "bundle":
            fpn = load_fpn(payload, device, path)
        else:
            source = fpn_weights or (payload.get("train_config") or {}).get("fpn_weights")
            if not source:
                raise InputError(
                    path, "is an AfANet checkpoint without the FPN it was trained with; give --fpn-weights"
                )
            fpn = load_fpn(source, device)
        afanet = load_afanet(payload, device, path)
        settings = GraphSettings.from_bundle(payload.get("inference", {}), path)
        if settings.reads_surface and not fpn.config.surface:
            raise InputError(
                path, "damaged weights file: a surface check or gate is set but the FPN has no surface head"
            )
        confidence = None
        if payload.get("confidence") is not None:
            confidence = EdgeConfidence.from_dict(payload["confidence"], path)
            if confidence.needs_surface and not fpn.config.surface:
                raise InputError(
                    path, "damaged weights file: the confidence reads the road surface but the FPN has no surface head"
                )
        pixel_size = payload.get("pixel_size_m", MODEL_GSD)
        if not isinstance(pixel_size, (int, float)) or not (0.01 <= pixel_size <= 5.0):
            raise InputError(path, f"damaged weights file: pixel_size_m = {pixel_size!r} is not a pixel size in metres")
        return cls(fpn, afanet, device, settings=settings, pixel_size_m=float(pixel_size), confidence=confidence)

    def maps(self, image: np.ndarray) -> np.ndarray:
        return self.patch_maps([None], [image])[0]

    def patch_maps(self, patches: list, images: list[np.ndarray]) -> list[np.ndarray]:
        """FPN maps of several patches in one batch (the city pipeline's ``PatchModel`` step):
        keypoint and boundary, plus the road surface when the surface check is on."""
        batch = np.stack(images)
        if self.onnx is not None and self.precision != "bfloat16" and batch.shape[-2:] == (WINDOW, WINDOW):
            probs = torch.sigmoid(
                torch.from_numpy(self.onnx.fpn_logits(unit_bands(batch), int8=self.precision == "int8"))
            ).numpy()
        else:
            if self.precision == "int8":
                warnings.warn(
                    f"the int8 FPN is made for {WINDOW} px windows: this {batch.shape[-1]} x {batch.shape[-2]} px image "
                    "runs in float32",
                    InputWarning,
                    stacklevel=2,
                )
            probs = predict_probabilities(
                self.fpn if self.folded_fpn is None else self.folded_fpn, batch, self.device, self.precision
            )
        if (
            not self.reads_surface
        ):  # the surface channel is carried (stitched, stored, written) only when the check or gate reads it
            probs = probs[:, :SURFACE]
        return list(probs)

    @property
    def reads_surface(self) -> bool:
        """Whether the road-surface map is used (check, gate or the edges' evidence), so carried
        with the others."""
        evidence = self.confidence is not None or self.collect_evidence
        return self.settings.reads_surface or (evidence and self.fpn.config.surface)

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        """Vertices (and corner edges) of a patch's keypoint map, plus, when ``crossings`` is on,
        the boundary map's crossings with the grid lines (:mod:`csboundary.graph.crossings`); with
        the gate on, of the maps gated by the surface (:mod:`csboundary.graph.surface_gate`)."""
        settings = self.settings
        maps = gated_maps(maps, SURFACE, settings.gate)
        found = extract_vertices(maps[0], settings.vertices)
        extra = added_crossings(found, maps[1], settings.crossings)
        if not len(extra):
            return found
        return BoundaryGraph(
            np.concatenate([found.vertices, extra]),
            found.edges,
            vertex_kinds=list(found.vertex_kinds or []) + ["isolated"] * len(extra),
            edge_kinds=found.edge_kinds,
            edge_polylines=found.edge_polylines,
            edge_scores=found.edge_scores,
        )

    @torch.no_grad()
    def connect(self, patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        """The patch graph: ``found``'s vertices joined by its corner edges and AfANet's edges
        (AfANet, edge support and the steps after it see the gated maps when the gate is on)."""
        settings = self.settings
        maps = gated_maps(maps, SURFACE, settings.gate)
        m = found.n_vertices
        if m < 2:
            return self.finished(
                patch, maps, graph_from_adjacency(found, np.zeros((m, m)), settings.edge_threshold, settings.max_degree)
            )
        tensor = torch.from_numpy(bands_and_maps(image, maps)).to(self.device)
        vertices = torch.from_numpy(found.vertices.astype(np.float32)).to(self.device)
        if self.onnx is not None:  # the views (resized tensor, vertex windows) come from PyTorch either way
            views = [view.numpy() for view in self.afanet.views(tensor, vertices)]
            probs = adjacency_from_logits(torch.from_numpy(self.onnx.afanet_logits(*views))).numpy()
        else:
            probs = self.afanet.adjacency(tensor, vertices).cpu().numpy()
        for i, j in unsupported_pairs(found.vertices, probs, maps[1], settings.edge_threshold, settings.support):
            probs[i, j] = probs[j, i] = 0.0
        return self.finished(
            patch, maps, graph_from_adjacency(found, probs, settings.edge_threshold, settings.max_degree)
        )

    def finished(self, patch: Patch | None, maps: np.ndarray, graph: BoundaryGraph) -> BoundaryGraph:
        """``graph`` filled in from the skeleton (``fill``), then without the edges no roadway
        borders (``surface``), then with the roadway's sure outline in place of the edges along
        it (``outline``); the last two when the maps carry the FPN's surface channel."""
        graph = join_ends(self.filled(patch, maps, graph), maps[1], self.settings.join)
        if self.settings.surface.active and maps.shape[0] > SURFACE:
            graph = surface_checked(graph, maps[SURFACE], self.settings.surface)
        if self.settings.outline.active and maps.shape[0] > SURFACE:
            graph = fused_with_outline(graph, maps[SURFACE], maps[1], self.settings.outline, core_region(patch))
        return graph

    def filled(self, patch: Patch | None, maps: np.ndarray, graph: BoundaryGraph) -> BoundaryGraph:
        """``graph`` with the boundary it missed filled in from the segmentation skeleton
        (``fill``; off by default), in a city only inside the window's core and one pixel beyond,
        where the neighbouring window cuts the same skeleton (graph/skeleton_fill.py)."""
        if not self.settings.fill.active:
            return graph
        return fill_from_skeleton(graph, maps[1], self.settings.fill, core_region(patch))

    def graph(self, image: np.ndarray, maps: np.ndarray | None = None) -> BoundaryGraph:
        """Graph of one patch (pixel coordinates of ``image``); ``maps`` when already stitched."""
        if maps is None:
            maps = self.maps(image)
        return self.connect(None, image, maps, self.extract(maps))


def core_region(patch: Patch | None) -> tuple[int, int, int, int] | None:
    """(row0, row1, col0, col1) of a window's core and one pixel beyond, in the window's pixels,
    where steps that add edges from the maps may add them (None: a lone patch, everywhere)."""
    if patch is None:
        return None
    core = patch.core_local
    return core.row_off, core.row_end + 1, core.col_off, core.col_end + 1


def faster_fpn(seconds: dict[str, float]) -> tuple[str, str]:
    """``int8`` or ``float32``, whichever FPN ran faster when ONNX Runtime's levels were timed on
    this machine (``seconds``: the fastest run of ``fpn`` and ``fpn-int8``), and why, in words."""
    f32, q8 = seconds.get("fpn"), seconds.get("fpn-int8")
    if not f32 or not q8:
        return "float32", "float32 (the FPN was not timed in int8 on this machine)"
    if q8 < f32:
        return "int8", (
            f"int8: its FPN ran in {q8 * 1000:.0f} ms against {f32 * 1000:.0f} ms in float32 on this CPU "
            "(--precision float32 forces float32)"
        )
    return "float32", f"float32: its FPN ran in {f32 * 1000:.0f} ms against {q8 * 1000:.0f} ms in int8 on this CPU"


def load_predictor(
    weights: str | Path | None = None,
    device: str = "auto",
    graph: GraphOverrides = GraphOverrides(),
    *,
    fpn_weights: str | Path | None = None,
    engine: str = "auto",
    precision: str = "float32",
) -> PatchPredictor:
    """The predictor of a weights bundle (the shipped one by default) with the command line's
    ``graph`` options over its settings, on the chosen engine (``auto``: ONNX Runtime on a CPU
    when installed) and device (``auto``: CUDA if present)."""
    predictor = PatchPredictor.load(weights, resolve_device(device), fpn_weights)
    predictor.override(graph)
    predictor.use_precision(precision)
    predictor.use_engine(engine, weights, fpn_weights)
    return predictor
