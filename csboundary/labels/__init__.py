"""Training labels from vector ground truth (paper Sections IV-B, IV-C, V-B).

Everything is computed once in global (mosaic) pixel coordinates and only then cut per patch,
so overlapping patches agree exactly: ``boundaries`` (ground truth as pixel polylines),
``keypoints`` (curvature and intersection keypoints), ``rasterize`` (segmentation, orientation,
keypoint heat), ``patch_graph`` (the ground-truth graph of a patch), ``adjacency`` (adjacency
labels for any vertex set), ``writer`` (all labels of a city, to disk).
"""

from csboundary.labels.config import LabelConfig

__all__ = ["LabelConfig"]
