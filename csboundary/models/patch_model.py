"""What every model of the city pipeline implements: the trained networks, the baselines and the
ground-truth oracle alike. The pipeline (:mod:`csboundary.pipeline.prediction.city`) runs any
object with these steps, so a model is defined here, beside the models, not by its user."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from csboundary.data.grid import Patch
from csboundary.graph import BoundaryGraph
from csboundary.graph.settings import GraphSettings
from csboundary.models.confidence_model import EdgeConfidence


class PatchModel(Protocol):
    """Three steps per patch, the graph settings the city graph reads (``min_fragment_px``,
    ``attach_px``, ``min_confidence``), an edge confidence (None: scores as found), whether to keep
    the maps the edges' evidence is read from, and the pixel size it takes imagery at."""

    settings: GraphSettings
    confidence: EdgeConfidence | None
    collect_evidence: bool
    pixel_size_m: float  # the pixel size the model takes imagery at

    def patch_maps(self, patches: list[Patch], images: list[np.ndarray]) -> list[np.ndarray]:
        """(C, S, S) probabilities per patch (C = 2: keypoint and segmentation)."""

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        """Vertices and corner edges of a stitched window (window pixels)."""

    def connect(self, patch: Patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        """The window's graph: ``found`` plus the predicted edges."""
