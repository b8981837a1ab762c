"""One patch, end to end: FPN maps -> vertices -> AfANet adjacency -> graph (paper Alg. 1 body).

The returned graph has the extracted vertices; its edges are the corner edges of gathered runs
(kind ``corner``, with the skeleton polyline, score 1) and the AfANet edges (kind ``normal``,
score = symmetric adjacency probability).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import torch
from shapely.geometry import LineString

from csboundary.graph import BoundaryGraph
from csboundary.graph.crossings import CrossingConfig, added_crossings
from csboundary.graph.edge_support import EdgeSupportConfig, unsupported_pairs
from csboundary.graph.vertex_extraction import VertexConfig, extract_vertices
from csboundary.models.afanet import AfANet, AfANetConfig, edges_from_adjacency
from csboundary.models.checkpoint import load_checkpoint, load_fpn
from csboundary.models.fpn import FPN
from csboundary.pipeline.maps import image_tensor, predict_probabilities

SHIPPED_WEIGHTS = "csboundary-synthetic.pt"
CORNER_SIMPLIFY_PX = 0.75  # skeleton staircases -> smooth polylines (they are ~5 % too long otherwise)


def _smooth(polyline: np.ndarray | None) -> np.ndarray | None:
    """A corner edge's skeleton path without its pixel staircase (Douglas-Peucker, ends kept)."""
    if polyline is None or len(polyline) < 3:
        return polyline
    return np.asarray(LineString(polyline).simplify(CORNER_SIMPLIFY_PX).coords)


def shipped_weights() -> Path:
    """Path of the weights shipped inside the package (trained by ``csboundary train``)."""
    return Path(str(resources.files("csboundary") / "weights" / SHIPPED_WEIGHTS))


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

    @classmethod
    def load(cls, weights: str | Path | None, device: torch.device, fpn_weights: str | Path | None = None) -> "PatchPredictor":
        """From a bundle (both models; the shipped one by default), or an AfANet checkpoint plus
        ``fpn_weights``."""
        path = Path(weights) if weights else shipped_weights()
        payload = load_checkpoint(path, ("bundle", "afanet"), map_location=device)
        fpn = load_fpn(payload if payload["kind"] == "bundle" else fpn_weights or payload["train_config"]["fpn_weights"], device)
        afanet = AfANet(AfANetConfig.from_dict(payload["afanet_config"])).to(device).eval()
        afanet.load_state_dict(payload["afanet"])
        settings = payload.get("inference", {})
        support = EdgeSupportConfig(**{k: settings[k] for k in ("min_support", "max_length_px", "radius_px") if k in settings})
        crossings = CrossingConfig(spacing_px=int(settings.get("crossing_spacing_px", 0)))
        return cls(fpn, afanet, device, edge_threshold=settings.get("edge_threshold", 0.5), max_degree=settings.get("max_degree", 2),
                   support=support, crossings=crossings)

    def maps(self, image: np.ndarray) -> np.ndarray:
        return predict_probabilities(self.fpn, image, self.device)

    def patch_maps(self, patches: list, images: list[np.ndarray]) -> list[np.ndarray]:
        """FPN maps of several patches in one batch (the city pipeline's ``PatchModel`` step)."""
        return list(predict_probabilities(self.fpn, np.stack(images), self.device))

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        """Vertices (and corner edges) of a patch's keypoint map, plus, when ``crossings`` is on,
        the boundary map's crossings with the grid lines (:mod:`csboundary.graph.crossings`)."""
        found = extract_vertices(maps[0], self.vertices)
        extra = added_crossings(found, maps[1], self.crossings)
        if not len(extra):
            return found
        return BoundaryGraph(np.concatenate([found.vertices, extra]), found.edges,
                             vertex_kinds=list(found.vertex_kinds or []) + ["isolated"] * len(extra),
                             edge_kinds=found.edge_kinds, edge_polylines=found.edge_polylines, edge_scores=found.edge_scores)

    @torch.no_grad()
    def connect(self, patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        """The patch graph: ``found``'s vertices joined by its corner edges and AfANet's edges."""
        m = found.n_vertices
        if m < 2:
            return graph_from_adjacency(found, np.zeros((m, m)), self.edge_threshold, self.max_degree)
        tensor = torch.cat([image_tensor(image, self.device), torch.from_numpy(np.ascontiguousarray(maps)).to(self.device)], dim=0)
        vertices = torch.from_numpy(found.vertices.astype(np.float32)).to(self.device)
        probs = self.afanet.adjacency(tensor, vertices).cpu().numpy()
        for i, j in unsupported_pairs(found.vertices, probs, maps[1], self.edge_threshold, self.support):
            probs[i, j] = probs[j, i] = 0.0
        return graph_from_adjacency(found, probs, self.edge_threshold, self.max_degree)

    def graph(self, image: np.ndarray, maps: np.ndarray | None = None) -> BoundaryGraph:
        """Graph of one patch (pixel coordinates of ``image``); ``maps`` when already stitched."""
        if maps is None:
            maps = self.maps(image)
        return self.connect(None, image, maps, self.extract(maps))


def graph_from_adjacency(found: BoundaryGraph, probs: np.ndarray, threshold: float, max_degree: int | None) -> BoundaryGraph:
    """Extracted vertices + an (M, M) edge probability matrix -> the patch graph.

    Corner edges from vertex extraction are always kept (kind ``corner``, their skeleton smoothed
    into the polyline, score = mean keypoint probability along it); the other edges are decoded
    from ``probs`` (kind ``normal``, score = their probability).
    """
    corner = [tuple(int(x) for x in e) for e in found.edges]
    polylines = {tuple(sorted(e)): _smooth(found.edge_polylines[k]) for k, e in enumerate(corner)} if found.edge_polylines else {}
    corner_scores = {tuple(sorted(e)): float(found.edge_scores[k]) for k, e in enumerate(corner)} if found.edge_scores is not None else {}
    edges = edges_from_adjacency(torch.as_tensor(probs, dtype=torch.float32), threshold, max_degree, fixed=corner) if len(probs) >= 2 else [tuple(sorted(e)) for e in corner]
    kinds, lines, scores = [], [], []
    for u, v in edges:
        line = polylines.get((u, v))
        if line is not None:
            line = np.asarray(line)
            if np.linalg.norm(line[0] - found.vertices[u]) > np.linalg.norm(line[0] - found.vertices[v]):
                line = line[::-1]
        kinds.append("corner" if line is not None else "normal")
        lines.append(line)
        scores.append(corner_scores.get((u, v), 1.0) if line is not None else float(probs[u, v]))
    return BoundaryGraph(found.vertices, np.array(edges, dtype=np.int64).reshape(-1, 2), vertex_kinds=found.vertex_kinds,
                         edge_kinds=kinds, edge_polylines=lines, edge_scores=np.array(scores, dtype=float))
