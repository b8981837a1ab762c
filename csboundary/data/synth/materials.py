"""The palette: every material's colour (R, G, B, NIR) and the small random shade changes that
keep two lawns or two roofs from looking alike. Colours only, no geometry.
"""

from __future__ import annotations

import numpy as np

Colour = tuple[int, int, int, int]  # R, G, B, NIR

# Materials: base colour and texture roughness (noise amplitude). Vegetation is bright in NIR.
ASPHALT: Colour = (78, 80, 84, 70)
CONCRETE: Colour = (168, 163, 154, 150)
GRASS: Colour = (82, 108, 56, 205)
SOIL: Colour = (122, 108, 88, 128)
PARKING: Colour = (92, 92, 95, 82)
WHITE_PAINT: Colour = (226, 226, 220, 200)
YELLOW_PAINT: Colour = (214, 176, 64, 165)
GRAVEL: Colour = (140, 128, 110, 125)
HEDGE: Colour = (46, 72, 38, 175)
FENCES: tuple[Colour, ...] = ((150, 128, 98, 120), (122, 120, 116, 110), (62, 58, 54, 60), (205, 200, 190, 175))
WATER: Colour = (70, 162, 192, 40)  # pools: bright cyan, dark in NIR
DRIVEWAYS: tuple[Colour, ...] = (ASPHALT, (58, 60, 64, 54), CONCRETE, PARKING, (150, 145, 138, 132))
# Per-city material choices (config ``road_materials`` / ``sidewalk_materials`` / ``roof_palette``).
ROAD_MATERIALS: dict[str, Colour] = {
    "asphalt": ASPHALT,
    "asphalt_new": (46, 48, 52, 44),
    "asphalt_old": (118, 117, 113, 104),
    "asphalt_warm": (98, 90, 82, 80),
    "concrete_road": (150, 148, 141, 134),
}
SIDEWALK_MATERIALS: dict[str, Colour] = {
    "concrete": CONCRETE,
    "concrete_dark": (132, 129, 123, 118),
    "pavers_red": (152, 108, 92, 118),
    "pavers_grey": (141, 139, 134, 126),
    "asphalt_walk": (96, 96, 98, 86),
}
ROOF_PALETTES = ("grey", "warm", "dark", "mixed", "tar")  # tar: flat tar, gravel and membrane roofs
CROP_COLOURS: tuple[Colour, ...] = (
    (96, 128, 60, 215),
    (150, 140, 84, 170),
    (118, 100, 74, 120),
    (70, 104, 48, 225),
    (176, 160, 104, 160),
)
# Car colours as seen in dense-city photographs: mostly white, black, silver and grey, a few saturated.
CAR_PHOTO_COLOURS: tuple[tuple[Colour, float], ...] = (
    ((232, 233, 230, 200), 0.24),
    ((28, 29, 33, 30), 0.2),
    ((178, 181, 185, 150), 0.14),
    ((105, 108, 114, 95), 0.14),
    ((52, 58, 70, 55), 0.07),
    ((150, 32, 32, 70), 0.06),
    ((32, 58, 118, 60), 0.05),
    ((120, 96, 70, 90), 0.04),
    ((225, 190, 45, 160), 0.03),
    ((60, 96, 60, 80), 0.03),
)
WINDOW: Colour = (38, 44, 52, 40)  # windshields and rear windows: dark glass
TAR_ROOFS: tuple[Colour, ...] = (
    (120, 120, 118, 108),
    (64, 64, 66, 58),
    (212, 214, 212, 190),
    (186, 186, 182, 165),
    (158, 150, 138, 140),
    (92, 90, 88, 80),
)
# turf, then courts: red, green, red
COURTS: tuple[Colour, ...] = ((50, 78, 50, 60), (140, 78, 66, 96), (70, 108, 82, 90), (134, 84, 72, 90))
CAR_COLOURS: tuple[Colour, ...] = (
    (235, 235, 232, 205),
    (25, 26, 30, 30),
    (160, 163, 168, 140),
    (100, 102, 108, 90),
    (150, 30, 30, 70),
    (35, 55, 120, 60),
    (40, 70, 50, 70),
    (225, 185, 40, 160),
    (200, 200, 205, 175),
)


def jitter_colour(rng: np.random.Generator, colour: Colour, amount: float) -> Colour:
    """``colour`` brightened or darkened by up to ``amount`` (a fraction) and each band nudged by
    up to 6, clipped to 0..255: two lawns or two roofs of one material never look alike."""
    scale = 1 + rng.uniform(-amount, amount)
    return tuple(int(np.clip(c * scale + rng.uniform(-6, 6), 0, 255)) for c in colour)  # type: ignore[return-value]


def scaled_colour(colour: Colour, factor: float) -> Colour:
    """``colour`` brightened or darkened by ``factor``, each band truncated to 0..255."""
    return tuple(int(np.clip(c * factor, 0, 255)) for c in colour)  # type: ignore[return-value]
