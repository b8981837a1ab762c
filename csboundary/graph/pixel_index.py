"""Where a 2-D map is non-zero, fast: the pixel lists every map-reading step starts from."""

from __future__ import annotations

import numpy as np


def nonzero_pixels(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the non-zero pixels of a 2-D array in raster order: ``np.nonzero``'s
    answer, computed as the 1-D ``np.flatnonzero`` split by ``divmod``. NumPy's 2-D ``nonzero``
    takes 3-5 ms on an 1100 x 1100 map however few pixels are set; this takes ~0.4 ms on the
    sparse masks of keypoint and boundary maps, and vertex extraction and the skeleton fill
    ask it several times per window."""
    image = np.asarray(image)
    if image.ndim != 2:
        raise ValueError(f"expected a 2-D array, got shape {image.shape}")
    rows, cols = np.divmod(np.flatnonzero(image), max(image.shape[1], 1))
    return rows, cols
