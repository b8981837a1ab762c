"""One patch, end to end: FPN maps -> vertices -> AfANet adjacency -> graph (paper Alg. 1 body).

The returned graph has the extracted vertices; its edges are the corner edges of gathered runs
(kind ``corner``, with the skeleton polyline, score = mean keypoint probability along it), the
AfANet edges (kind ``normal``, score = symmetric adjacency probability) and, when the fill is on,
the boundary both missed, from the segmentation skeleton (kind ``skeleton``, score = mean
boundary probability along it; graph/skeleton_fill.py); with an FPN that maps the road surface
and the surface check on, edges with no roadway beside them are then dropped
(graph/surface_check.py). With a bundle that has an edge confidence, the city graph's scores are
then replaced by it (pipeline/edge_confidence.py).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from csboundary.data.grid import Patch
from csboundary.data.units import MODEL_GSD
from csboundary.errors import InputError, InputWarning
from csboundary.graph import BoundaryGraph
from csboundary.graph.crossings import CrossingConfig, added_crossings
from csboundary.graph.edge_support import EdgeSupportConfig, unsupported_pairs
from csboundary.graph.end_joining import EndJoinConfig, join_ends
from csboundary.graph.skeleton_fill import FillConfig, fill_from_skeleton
from csboundary.graph.surface_check import SurfaceCheckConfig, surface_checked
from csboundary.graph.surface_gate import SurfaceGateConfig, gated_maps
from csboundary.graph.vertex_extraction import VertexConfig, extract_vertices
from csboundary.models.afanet import AfANet, adjacency_from_logits
from csboundary.models.batchnorm_folding import fold_batch_norms
from csboundary.models.checkpoint import load_afanet, load_checkpoint, load_fpn, shipped_weights
from csboundary.models.confidence import EdgeConfidence
from csboundary.models.decoding import graph_from_adjacency
from csboundary.models.fpn import FPN, SURFACE
from csboundary.models.device import bfloat16_hardware
from csboundary.models.maps import PRECISIONS, bands_and_maps, predict_probabilities, unit_bands
from csboundary.models.onnx_engine import OnnxNetworks
from csboundary.models.onnx_session import WINDOW, onnxruntime_available


@dataclass
class PatchPredictor:
    fpn: FPN
    afanet: AfANet
    device: torch.device
    vertices: VertexConfig = field(default_factory=VertexConfig)
    edge_threshold: float = 0.5
    max_degree: int | None = 2
    support: EdgeSupportConfig = field(default_factory=EdgeSupportConfig)  # AfANet edges the boundary map must back
    crossings: CrossingConfig = field(default_factory=CrossingConfig)  # extra vertices on the grid lines (off by default)
    fill: FillConfig = field(default_factory=FillConfig)  # boundary the graph missed, from the segmentation skeleton (off by default)
    surface: SurfaceCheckConfig = field(default_factory=SurfaceCheckConfig)  # edges need roadway beside them (FPNs with a surface head; off by default)
    join: EndJoinConfig = field(default_factory=EndJoinConfig)  # dangling ends joined across supported gaps (off by default)
    gate: SurfaceGateConfig = field(default_factory=SurfaceGateConfig)  # keypoint and boundary maps only where the surface changes (off by default)
    pixel_size_m: float = MODEL_GSD  # the training imagery's pixel size: input is resampled to it
    min_fragment_px: float = 0.0  # city graph: connected pieces shorter than this are dropped (graph/fragments.py; 0 = off)
    attach_px: float = 0.0  # city graph: dangling ends joined to the line ahead within this (graph/end_attachment.py; 0 = off)
    onnx: OnnxNetworks | None = None  # the networks on ONNX Runtime (CPU), see use_engine
    precision: str = "float32"  # the FPN's arithmetic, see use_precision
    precision_choice: str | None = None  # how ``auto`` chose it, in words (None: asked for by name)
    folded_fpn: torch.nn.Module | None = field(default=None, repr=False)  # the FPN with batch norms folded, for bfloat16
    confidence: EdgeConfidence | None = None  # the city graph's edge confidence (models/confidence.py; None: scores as found)
    min_confidence: float = 0.0  # city graph: edges less sure than this are dropped (0 = keep all)
    collect_evidence: bool = False  # keep the maps the edges' evidence is read from (to fit a confidence)

    @property
    def engine(self) -> str:
        return "onnx" if self.onnx is not None else "torch"

    def use_engine(self, engine: str, weights: str | Path | None = None, fpn_weights: str | Path | None = None) -> str:
        """``torch``, ``onnx`` (ONNX Runtime, CPU only) or ``auto`` (onnx on a CPU when
        onnxruntime is installed); returns the engine chosen. ``weights`` (and ``fpn_weights``)
        are the files the networks came from (default: the shipped bundle): the export is cached
        under their hash."""
        if engine not in ("auto", "torch", "onnx"):
            raise InputError("--engine", f"unknown engine {engine!r} (auto, torch or onnx)")
        on_cpu = self.device.type == "cpu"
        if engine == "onnx" and not on_cpu:
            raise InputError("--engine", f"the onnx engine runs on the CPU, not {self.device}; use --device cpu or --engine torch")
        if engine == "onnx" and not onnxruntime_available():
            raise InputError("--engine", "onnxruntime is not installed (pip install 'csboundary[onnx]')")
        if engine == "torch" or (engine == "auto" and not (on_cpu and onnxruntime_available())):
            if self.precision == "int8":
                raise InputError("--precision", "int8 runs the FPN on ONNX Runtime: use --engine onnx or auto "
                                                "(on a CPU, with onnxruntime installed: pip install 'csboundary[onnx]')")
            if self.precision == "auto":
                self.precision, self.precision_choice = "float32", "float32: the torch engine runs the FPN in float32"
            self.onnx = None
            return "torch"
        from csboundary.models.checkpoint import file_sha256

        path = Path(weights) if weights else shipped_weights()
        digest = file_sha256(path)
        if fpn_weights:  # both files decide the networks
            import hashlib

            digest = hashlib.sha256((digest + file_sha256(fpn_weights)).encode()).hexdigest()
        self.onnx = OnnxNetworks.for_weights(path, digest, self.fpn, self.afanet, int8=self.precision in ("int8", "auto"))
        if self.precision == "auto":
            self.precision, self.precision_choice = faster_fpn(self.onnx.fpn_seconds())
        if self.precision == "int8":
            self.onnx.spare_a_core()
        return "onnx"

    def use_precision(self, precision: str) -> None:
        """``auto`` (int8 where this CPU runs the quantized FPN faster than the float32 one on
        ONNX Runtime, timed on first use; else float32: :func:`faster_fpn`), ``float32``, ``bfloat16`` (the FPN in PyTorch under bfloat16 autocast, whatever the
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
            raise InputError("--precision", f"int8 runs the FPN on ONNX Runtime on the CPU, not {self.device}; use --device cpu")
        if precision == "bfloat16" and not bfloat16_hardware(self.device):
            if self.device.type == "cuda":
                raise InputError("--precision", f"{torch.cuda.get_device_name(self.device)} has no bfloat16 support; use float32")
            warnings.warn("this CPU has no bfloat16 units (AMX or AVX512-BF16): --precision bfloat16 will be slower than float32", InputWarning)
        self.precision = precision
        self.folded_fpn = fold_batch_norms(self.fpn) if precision == "bfloat16" else None

    @classmethod
    def load(cls, weights: str | Path | None, device: torch.device, fpn_weights: str | Path | None = None) -> "PatchPredictor":
        """From a bundle (both models; the shipped one by default), or an AfANet checkpoint plus
        ``fpn_weights``."""
        path = Path(weights) if weights else shipped_weights()
        payload = load_checkpoint(path, ("bundle", "afanet"), map_location=device)
        if payload["kind"] == "bundle":
            fpn = load_fpn(payload, device, path)
        else:
            source = fpn_weights or (payload.get("train_config") or {}).get("fpn_weights")
            if not source:
                raise InputError(path, "is an AfANet checkpoint without the FPN it was trained with; give --fpn-weights")
            fpn = load_fpn(source, device)
        afanet = load_afanet(payload, device, path)
        settings = inference_settings(payload.get("inference", {}), path)
        support = EdgeSupportConfig(**{k: settings[k] for k in ("min_support", "max_length_px", "radius_px", "max_gap_px", "gap_level") if k in settings})
        crossings = CrossingConfig(spacing_px=int(settings.get("crossing_spacing_px", 0)))
        fill = FillConfig(min_length_px=float(settings.get("fill_min_length_px", 0.0)))
        join = EndJoinConfig(max_px=float(settings.get("join_max_px", 0.0)), attach_px=float(settings.get("join_attach_px", 0.0)))
        surface = SurfaceCheckConfig(**{field: float(settings[key]) for key, field in SURFACE_SETTINGS.items() if key in settings})
        gate = SurfaceGateConfig(**{field: kind(settings[key]) for key, (field, kind) in GATE_SETTINGS.items() if key in settings})
        if (surface.active or gate.active) and not fpn.config.surface:
            raise InputError(path, "damaged weights file: a surface check or gate is set but the FPN has no surface head")
        confidence = None
        if payload.get("confidence") is not None:
            confidence = EdgeConfidence.from_dict(payload["confidence"], path)
            if confidence.needs_surface and not fpn.config.surface:
                raise InputError(path, "damaged weights file: the confidence reads the road surface but the FPN has no surface head")
        pixel_size = payload.get("pixel_size_m", MODEL_GSD)
        if not isinstance(pixel_size, (int, float)) or not (0.01 <= pixel_size <= 5.0):
            raise InputError(path, f"damaged weights file: pixel_size_m = {pixel_size!r} is not a pixel size in metres")
        return cls(fpn, afanet, device, vertices=VertexConfig(threshold=float(settings.get("vertex_threshold", 0.5))),
                   edge_threshold=settings.get("edge_threshold", 0.5), max_degree=settings.get("max_degree", 2),
                   support=support, crossings=crossings, fill=fill, surface=surface, join=join, gate=gate, pixel_size_m=float(pixel_size),
                   min_fragment_px=float(settings.get("min_fragment_px", 0.0)), attach_px=float(settings.get("attach_max_px", 0.0)),
                   confidence=confidence)

    def maps(self, image: np.ndarray) -> np.ndarray:
        return self.patch_maps([None], [image])[0]

    def patch_maps(self, patches: list, images: list[np.ndarray]) -> list[np.ndarray]:
        """FPN maps of several patches in one batch (the city pipeline's ``PatchModel`` step):
        keypoint and boundary, plus the road surface when the surface check is on."""
        batch = np.stack(images)
        if self.onnx is not None and self.precision != "bfloat16" and batch.shape[-2:] == (WINDOW, WINDOW):
            probs = torch.sigmoid(torch.from_numpy(self.onnx.fpn_logits(unit_bands(batch), int8=self.precision == "int8"))).numpy()
        else:
            if self.precision == "int8":
                warnings.warn(f"the int8 FPN is made for {WINDOW} px windows: this {batch.shape[-1]} x {batch.shape[-2]} px image "
                              "runs in float32", InputWarning)
            probs = predict_probabilities(self.fpn if self.folded_fpn is None else self.folded_fpn, batch, self.device, self.precision)
        if not self.reads_surface:  # the surface channel is carried (stitched, stored, written) only when the check or gate reads it
            probs = probs[:, :SURFACE]
        return list(probs)

    @property
    def reads_surface(self) -> bool:
        """Whether the road-surface map is used (check, gate or the edges' evidence), so carried
        with the others."""
        evidence = self.confidence is not None or self.collect_evidence
        return self.surface.active or self.gate.active or (evidence and self.fpn.config.surface)

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        """Vertices (and corner edges) of a patch's keypoint map, plus, when ``crossings`` is on,
        the boundary map's crossings with the grid lines (:mod:`csboundary.graph.crossings`); with
        the gate on, of the maps gated by the surface (:mod:`csboundary.graph.surface_gate`)."""
        maps = gated_maps(maps, SURFACE, self.gate)
        found = extract_vertices(maps[0], self.vertices)
        extra = added_crossings(found, maps[1], self.crossings)
        if not len(extra):
            return found
        return BoundaryGraph(np.concatenate([found.vertices, extra]), found.edges,
                             vertex_kinds=list(found.vertex_kinds or []) + ["isolated"] * len(extra),
                             edge_kinds=found.edge_kinds, edge_polylines=found.edge_polylines, edge_scores=found.edge_scores)

    @torch.no_grad()
    def connect(self, patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        """The patch graph: ``found``'s vertices joined by its corner edges and AfANet's edges
        (AfANet, edge support and the steps after it see the gated maps when the gate is on)."""
        maps = gated_maps(maps, SURFACE, self.gate)
        m = found.n_vertices
        if m < 2:
            return self.finished(patch, maps, graph_from_adjacency(found, np.zeros((m, m)), self.edge_threshold, self.max_degree))
        tensor = torch.from_numpy(bands_and_maps(image, maps)).to(self.device)
        vertices = torch.from_numpy(found.vertices.astype(np.float32)).to(self.device)
        if self.onnx is not None:  # the views (resized tensor, vertex windows) come from PyTorch either way
            views = [view.numpy() for view in self.afanet.views(tensor, vertices)]
            probs = adjacency_from_logits(torch.from_numpy(self.onnx.afanet_logits(*views))).numpy()
        else:
            probs = self.afanet.adjacency(tensor, vertices).cpu().numpy()
        for i, j in unsupported_pairs(found.vertices, probs, maps[1], self.edge_threshold, self.support):
            probs[i, j] = probs[j, i] = 0.0
        return self.finished(patch, maps, graph_from_adjacency(found, probs, self.edge_threshold, self.max_degree))

    def finished(self, patch: Patch | None, maps: np.ndarray, graph: BoundaryGraph) -> BoundaryGraph:
        """``graph`` filled in from the skeleton (``fill``), then without the edges no roadway
        borders (``surface``, when the maps carry the FPN's surface channel)."""
        graph = join_ends(self.filled(patch, maps, graph), maps[1], self.join)
        if self.surface.active and maps.shape[0] > SURFACE:
            graph = surface_checked(graph, maps[SURFACE], self.surface)
        return graph

    def filled(self, patch: Patch | None, maps: np.ndarray, graph: BoundaryGraph) -> BoundaryGraph:
        """``graph`` with the boundary it missed filled in from the segmentation skeleton
        (``fill``; off by default), in a city only inside the window's core and one pixel beyond,
        where the neighbouring window cuts the same skeleton (graph/skeleton_fill.py)."""
        if not self.fill.active:
            return graph
        region = None
        if patch is not None:
            core = patch.core_local
            region = (core.row_off, core.row_end + 1, core.col_off, core.col_end + 1)
        return fill_from_skeleton(graph, maps[1], self.fill, region)

    def graph(self, image: np.ndarray, maps: np.ndarray | None = None) -> BoundaryGraph:
        """Graph of one patch (pixel coordinates of ``image``); ``maps`` when already stitched."""
        if maps is None:
            maps = self.maps(image)
        return self.connect(None, image, maps, self.extract(maps))


# name -> (smallest, largest, integer) of each inference setting a bundle may carry
INFERENCE_SETTINGS = {"edge_threshold": (0.0, 1.0, False), "max_degree": (0, 64, True), "min_support": (0.0, 1.0, False),
                      "max_length_px": (0.0, 1e6, False), "radius_px": (0.0, 100.0, False), "crossing_spacing_px": (0, 100000, True),
                      "min_fragment_px": (0.0, 1e6, False), "vertex_threshold": (0.01, 1.0, False), "max_gap_px": (0.0, 1e6, False),
                      "gap_level": (0.0, 1.0, False), "fill_min_length_px": (0.0, 1e6, False), "join_max_px": (0.0, 1e6, False), "join_attach_px": (0.0, 1e6, False),
                      "attach_max_px": (0.0, 1e6, False),
                      "surface_strong": (0.0, 1.0, False), "surface_weak": (0.0, 1.0, False), "surface_offset_px": (0.0, 100.0, False), "surface_both_sides": (0.0, 1.0, False),
                      "surface_gate_px": (0.0, 200.0, False), "surface_gate_full": (0.01, 1.0, False), "surface_gate_min_piece_px": (0, 10**8, True)}
SURFACE_SETTINGS = {"surface_strong": "strong", "surface_weak": "weak", "surface_offset_px": "offset_px", "surface_both_sides": "both_sides"}  # bundle key -> SurfaceCheckConfig field
GATE_SETTINGS = {"surface_gate_px": ("radius_px", float), "surface_gate_full": ("full_change", float),
                 "surface_gate_min_piece_px": ("min_piece_px", int)}  # bundle key -> SurfaceGateConfig field and type


def inference_settings(settings, path: str | Path) -> dict:
    """A bundle's inference settings, checked: an edge threshold of 7 or a degree cap of -1 would
    silently drop every edge, so an out-of-range or unknown value is an InputError naming the file."""
    if not isinstance(settings, dict):
        raise InputError(path, "damaged weights file: 'inference' is not a table of settings")
    for key, value in settings.items():
        if key not in INFERENCE_SETTINGS:
            raise InputError(path, f"unknown inference setting {key!r} (known: {', '.join(INFERENCE_SETTINGS)})")
        low, high, integer = INFERENCE_SETTINGS[key]
        if key == "max_degree" and value is None:
            continue
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and low <= value <= high
        if not ok or (integer and int(value) != value):
            kind = "an integer" if integer else "a number"
            raise InputError(path, f"inference setting {key} = {value!r} must be {kind} from {low:g} to {high:g}")
    return settings


def faster_fpn(seconds: dict[str, float]) -> tuple[str, str]:
    """``int8`` or ``float32``, whichever FPN ran faster when ONNX Runtime's levels were timed on
    this machine (``seconds``: the fastest run of ``fpn`` and ``fpn-int8``), and why, in words."""
    f32, q8 = seconds.get("fpn"), seconds.get("fpn-int8")
    if not f32 or not q8:
        return "float32", "float32 (the FPN was not timed in int8 on this machine)"
    if q8 < f32:
        return "int8", f"int8: its FPN ran in {q8 * 1000:.0f} ms against {f32 * 1000:.0f} ms in float32 on this CPU (--precision float32 forces float32)"
    return "float32", f"float32: its FPN ran in {f32 * 1000:.0f} ms against {q8 * 1000:.0f} ms in int8 on this CPU"


def load_predictor(weights: str | Path | None = None, device: str = "auto", *, edge_threshold: float | None = None,
                   min_edge_support: float | None = None, max_edge_length: float | None = None, max_edge_gap: float | None = None,
                   fill_min_length: float | None = None, surface_check: float | None = None, join_ends: float | None = None,
                   attach_ends: float | None = None, attach_backed: float | None = None, surface_gate: float | None = None,
                   max_degree: int | None = None,
                   min_fragment_length: float | None = None, fpn_weights: str | Path | None = None, engine: str = "auto",
                   precision: str = "float32", min_confidence: float | None = None) -> PatchPredictor:
    """The predictor of a weights bundle (the shipped one by default) with overrides of its
    inference settings (None keeps the bundle's; ``max_degree`` 0 means no cap), on the chosen
    engine (``auto``: ONNX Runtime on a CPU when installed) and device (``auto``: CUDA if present)."""
    import dataclasses

    from csboundary.models.device import resolve_device

    predictor = PatchPredictor.load(weights, resolve_device(device), fpn_weights)
    if edge_threshold is not None:
        predictor.edge_threshold = edge_threshold
    if min_edge_support is not None:
        predictor.support = dataclasses.replace(predictor.support, min_support=min_edge_support)
    if max_edge_length is not None:
        predictor.support = dataclasses.replace(predictor.support, max_length_px=max_edge_length)
    if max_edge_gap is not None:
        predictor.support = dataclasses.replace(predictor.support, max_gap_px=max_edge_gap)
    if fill_min_length is not None:
        predictor.fill = dataclasses.replace(predictor.fill, min_length_px=fill_min_length)
    if join_ends is not None:
        predictor.join = dataclasses.replace(predictor.join, max_px=join_ends)
    if attach_backed is not None:
        predictor.join = dataclasses.replace(predictor.join, attach_px=attach_backed)
    if attach_ends is not None:
        predictor.attach_px = attach_ends
    if surface_check is not None:
        if surface_check > 0 and not predictor.fpn.config.surface:
            raise InputError("--surface-check", "the FPN of these weights has no road-surface head")
        predictor.surface = dataclasses.replace(predictor.surface, strong=surface_check)
    if surface_gate is not None:
        if surface_gate > 0 and not predictor.fpn.config.surface:
            raise InputError("--surface-gate", "the FPN of these weights has no road-surface head")
        predictor.gate = dataclasses.replace(predictor.gate, radius_px=surface_gate)
    if max_degree is not None:
        predictor.max_degree = max_degree or None
    if min_fragment_length is not None:
        predictor.min_fragment_px = min_fragment_length
    if min_confidence:
        if predictor.confidence is None:
            raise InputError("--min-confidence", "these weights have no edge confidence (csboundary fit-confidence adds one)")
        predictor.min_confidence = min_confidence
    predictor.use_precision(precision)
    predictor.use_engine(engine, weights, fpn_weights)
    return predictor
