"""Every parameter of the metrics in one place, with the paper's values as defaults (pixels)."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class MetricConfig:
    """Parameters of all metrics. Lengths are pixels of the evaluation frame."""

    taus: tuple[float, ...] = (2.0, 5.0, 10.0)  # relaxation radii of precision/recall/F1 (strict <)
    # APLS (paper variant) and TLTS: shared sampled pairs
    spacing: float = 30.0  # resample every chain into pieces of at most this length
    snap_radius: float = (
        50.0  # a ground-truth endpoint further than this (or equal) from every predicted vertex costs 1
    )
    min_vertices: int = 5  # only boundaries with MORE sampled vertices than this get pairs
    pairs_divisor: int = 3  # a boundary of n sampled vertices gets n // 3 random pairs
    exhaustive_pairs: bool = False  # every pair of each boundary instead (exact; small graphs, tests)
    phi: float = 0.05  # TLTS: a pair is correct when |L_gt - L_pred| <= phi * L_gt
    # APLS (symmetric, SpaceNet style)
    sym_spacing: float = 30.0  # control-point spacing along edges
    sym_buffer: float = 10.0  # a control point snaps onto the other graph's nearest edge within this (inclusive)
    sym_max_pairs: int = (
        10000  # per direction: all within-component pairs up to this many, else a uniform sample of this many
    )
    sym_sources: int = 500  # ... drawn from this many source vertices (bounds the shortest-path searches)

    def __post_init__(self) -> None:
        if not self.taus or min(self.taus) <= 0:
            raise ValueError(f"taus must be positive, got {self.taus}")
        for name in ("spacing", "snap_radius", "sym_spacing", "sym_buffer"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if (
            self.pairs_divisor < 1
            or self.min_vertices < 1
            or self.sym_max_pairs < 1
            or self.sym_sources < 1
            or self.phi < 0
        ):
            raise ValueError("pairs_divisor, min_vertices, sym_max_pairs and sym_sources must be >= 1 and phi >= 0")

    def to_dict(self) -> dict:
        data = asdict(self)
        data["taus"] = list(self.taus)
        return data
