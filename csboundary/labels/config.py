"""Label parameters. The paper gives no numbers for these; each default is chosen and explained.

Pixel units throughout (the paper works in pixels of 0.152 m imagery).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from csboundary.config import Config
from csboundary.data.grid import GridConfig


@dataclass(frozen=True)
class LabelConfig(Config):
    config_name = "labels"
    grid: GridConfig = field(default_factory=GridConfig)
    # segmentation / orientation
    segmentation_width: int = 3  # px; boundary drawn this wide (issue default)
    orientation_bins: int = 64  # Topo-boundary's code: 64 bins of 5.625 deg, 0 = background
    # curvature keypoints
    turn_rate_deg_per_px: float = 0.4  # "direction changes by more than a threshold between
    #   neighbouring pixels": 0.4 deg/px = radius < 143 px (22 m at 0.152 m/px), above every
    #   curb return (3-12 m) and below gently curving streets
    smoothing_px: int = 9  # turning is averaged over this many 1 px steps (polygonised arcs)
    merge_gap_px: float = 24.0  # same-sign runs closer than this are one corner (coarse or
    #   simplified arcs: a 0.75 px Douglas-Peucker of a 12 m curb return has ~20 px chords)
    min_corner_turn_deg: float = 10.0  # a run turning less than this in total is noise
    gather_min_length_px: float = 12.0  # runs at least this long are gathered keypoints
    gradual_turn_deg: float = 20.0  # a gradual curve gets an isolated keypoint per this much turning
    # intersection keypoints
    aux_spacing_px: int = 250  # "extra lines": a finer global grid (issue default)
    min_separation_px: float = 2.0  # keypoints closer than this along a boundary are one
    # keypoint map
    heat_sigma_px: float = 3.0  # Gaussian sigma of keypoint heat
    # adjacency labels (paper V-B)
    snap_tolerance_px: float = 10.0  # a vertex farther than this from every boundary has no edges
