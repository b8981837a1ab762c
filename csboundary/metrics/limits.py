"""How large a graph the metrics accept, and the error beyond it.

A coordinate far outside the imagery would make a raster or a resampled graph as large as the
coordinate; the limits turn that into one clear error (the CLI reports it) instead of
exhausting memory. Both the pixel metrics and the resampling check against them here.
"""

from __future__ import annotations

MAX_SAMPLES = 20_000_000  # sampled points for APLS/TLTS; a 40 km city at 10 px spacing needs ~1e6
MAX_RASTER_PIXELS = 100_000_000  # ~3 GB of int64 work arrays; a 40 km city's boundaries need ~1e7


class RasterTooLarge(ValueError):
    """A graph would need more pixels or samples than the metrics' limits: a coordinate far
    outside the imagery (e.g. a label point at 2e9), not a real road network. ``size`` says how
    much was asked for, without the likely cause, for callers who know the cause is another
    (graphs already cut to the imagery)."""

    def __init__(self, size: str):
        super().__init__(size)
        self.size = size

    def __str__(self) -> str:
        return f"{self.size}: a coordinate lies far outside the imagery"
