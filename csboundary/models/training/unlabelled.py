"""Windows of a user's unlabelled imagery, drawn at random from mosaics of any size.

Self-training (``csboundary adapt``) learns from the imagery a user will map. Its cost must not
grow with the city, so nothing is read ahead: each sample reads one window from the mosaics
(as the model sees them, :func:`csboundary.data.model_view.model_view`), drawn where the imagery
lies (the files' footprint: tiles scattered over a city are not a mostly empty box) in proportion
to each mosaic's imagery, and a window mostly of no-data is drawn again.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from csboundary.data.footprint import draw_window, union_area
from csboundary.models.maps import unit_bands

MIN_VALID_SHARE = 0.5  # a window with less imagery than this is drawn again
DRAWS = 50  # windows tried before the best one seen is taken


class UnlabelledImagery:
    """Random windows of one or more mosaics (``views``: Mosaic-like, read at the model's pixel
    size), named by ``names`` in errors."""

    def __init__(self, views: Sequence, names: Sequence[str]):
        self.views, self.names = list(views), list(names)
        self.areas = np.array([union_area(v.footprint) for v in self.views], float)
        self.probabilities = self.areas / self.areas.sum()

    @property
    def pixels(self) -> int:
        """Pixels under the mosaics' files at the model's pixel size, no-data included."""
        return int(self.areas.sum())

    def sample(self, rng: np.random.Generator, side: int) -> tuple[np.ndarray, np.ndarray]:
        """A ``side`` square window: image (4, side, side) float32 in [0, 1] and valid (side, side)
        bool. Windows of a mosaic smaller than ``side`` cover all of it (the rest is invalid).
        Raises ValueError when :data:`DRAWS` windows hold no imagery at all."""
        best = None
        for _ in range(DRAWS):
            view = self.views[int(rng.choice(len(self.views), p=self.probabilities))]
            read = view.read(draw_window(rng, view.footprint, side))
            share = float(read.valid.mean())
            if best is None or share > best[0]:
                best = (share, read)
            if share >= MIN_VALID_SHARE:
                break
        share, read = best
        if share == 0:
            raise ValueError(f"{DRAWS} random windows of the imagery held no valid pixel (all no-data)")
        return unit_bands(read.data), read.valid
