"""A perfect "model" built from the ground truth, for the city pipeline's :class:`PatchModel` slot.

Its maps are the training labels (keypoint heat and segmentation) and its edges the adjacency
labels of whatever vertices were extracted. Fed through the real pipeline (streaming map
averaging, vertex extraction, graph stitching) it isolates the pipeline's own losses from the
networks' errors: the upper bound of the system, and the test that stitching keeps boundaries
whole across patch seams.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from csboundary.data.grid import Patch
from csboundary.data.raster import Mosaic
from csboundary.data.units import MODEL_GSD
from csboundary.graph import BoundaryGraph
from csboundary.graph.settings import GraphSettings
from csboundary.graph.vertex_extraction import extract_vertices
from csboundary.labels.adjacency import adjacency_label
from csboundary.labels.config import LabelConfig
from csboundary.labels.writer import CityLabels
from csboundary.models.decoding import graph_from_adjacency


@dataclass
class OracleModel:
    labels: CityLabels
    settings: GraphSettings = field(
        default_factory=lambda: GraphSettings(max_degree=None)
    )  # every labelled edge, no degree cap
    confidence = None  # the labels are sure
    collect_evidence = False
    pixel_size_m = MODEL_GSD

    @classmethod
    def from_lines(cls, lines, mosaic: Mosaic, config: LabelConfig = LabelConfig()) -> "OracleModel":
        """From ground-truth LineStrings in the mosaic's world coordinates."""
        return cls(CityLabels.build(lines, mosaic, config))

    def patch_maps(self, patches: list[Patch], images: list[np.ndarray]) -> list[np.ndarray]:
        return [self.labels.network_targets(p.expanded) for p in patches]

    def extract(self, maps: np.ndarray) -> BoundaryGraph:
        return extract_vertices(maps[0], self.settings.vertices)

    def connect(self, patch: Patch, image: np.ndarray, maps: np.ndarray, found: BoundaryGraph) -> BoundaryGraph:
        offset = np.array([patch.expanded.col_off, patch.expanded.row_off], float)
        lab = self.labels
        adjacency = adjacency_label(
            found.vertices + offset, lab.boundaries, lab.bounds, patch.expanded, lab.config.snap_tolerance_px
        )
        return graph_from_adjacency(
            found, adjacency.astype(np.float32), self.settings.edge_threshold, self.settings.max_degree
        )
