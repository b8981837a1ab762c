"""Paint one tile of a synthetic city: 4 bands (R, G, B, NIR), uint8.

Layers, bottom to top: asphalt everywhere; markings and crosswalks; blocks (sidewalks, lots,
islands, medians, driveways, yards), which clip any paint that ran over a curb; cars; shadows of
buildings and trees; buildings (flat roofs, or pitched ones as sunlit and shaded facets); tree
crowns. Then texture scaled by each material's roughness,
a low-frequency illumination field, a per-tile colour/brightness change and sensor noise.
Geometry is rasterised with OpenCV in 1/8-pixel fixed point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import shapely
from shapely.geometry import Polygon

from csboundary.data.synth.scene import ASPHALT, Scene, Tree

SHIFT = 3  # fixed-point bits for cv2 polygon vertices
SCALE = 1 << SHIFT


@dataclass(frozen=True)
class TileFrame:
    """A tile's extent in the city's local metres: x grows east from ``x0``, rows grow south from ``y1``."""

    x0: float
    y1: float
    size: int
    gsd: float

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        extent = self.size * self.gsd
        return self.x0, self.y1 - extent, self.x0 + extent, self.y1

    def to_pixels(self, coords: np.ndarray) -> np.ndarray:
        """Local metres (N, 2) -> fixed-point cv2 vertices (N, 2) int32 (cv2's pixel-centre frame)."""
        # OpenCV puts integer coordinates at pixel centres; ours put them at pixel corners.
        cols = (coords[:, 0] - self.x0) / self.gsd - 0.5
        rows = (self.y1 - coords[:, 1]) / self.gsd - 0.5
        return np.round(np.stack([cols, rows], axis=1) * SCALE).astype(np.int32)


def _contours(frame: TileFrame, polygon) -> list[np.ndarray]:
    contours = []
    for part in getattr(polygon, "geoms", [polygon]):
        if part.is_empty or part.geom_type != "Polygon":
            continue
        contours.append(frame.to_pixels(np.asarray(part.exterior.coords)))
        contours.extend(frame.to_pixels(np.asarray(r.coords)) for r in part.interiors)
    return contours


class _Canvas:
    """The colour image (rows, cols, 4) and a roughness map drawn in step with it."""

    def __init__(self, frame: TileFrame, road=ASPHALT):
        self.frame = frame
        self.image = np.empty((frame.size, frame.size, 4), np.uint8)
        self.image[:] = road
        self.rough = np.full((frame.size, frame.size), 4, np.uint8)
        x0, y0, x1, y1 = frame.bounds
        pad = 12.0
        self.clip = (x0 - pad, y0 - pad, x1 + pad, y1 + pad)

    def fill(self, polygon, colour, roughness: int) -> None:
        if polygon.is_empty:
            return
        minx, miny, maxx, maxy = polygon.bounds
        cx0, cy0, cx1, cy1 = self.clip
        if maxx < cx0 or maxy < cy0 or minx > cx1 or miny > cy1:
            return
        if minx < cx0 or miny < cy0 or maxx > cx1 or maxy > cy1:  # big polygons: cut to the tile first
            polygon = shapely.clip_by_rect(polygon, *self.clip)
        contours = _contours(self.frame, polygon)
        if contours:
            cv2.fillPoly(self.image, contours, colour, lineType=cv2.LINE_AA, shift=SHIFT)
            cv2.fillPoly(self.rough, contours, int(roughness), shift=SHIFT)

    def visible(self, polygon: Polygon) -> bool:
        minx, miny, maxx, maxy = polygon.bounds
        cx0, cy0, cx1, cy1 = self.clip
        return not (maxx < cx0 or maxy < cy0 or minx > cx1 or miny > cy1)


def render_tile(scene: Scene, frame: TileFrame, rng: np.random.Generator, noise_sigma: float = 5.0) -> np.ndarray:
    """Render the tile ``frame`` of ``scene`` as a (4, size, size) uint8 array.

    ``rng`` drives only per-tile appearance (illumination, colour, noise), so geometry is the
    same whichever tiles are rendered and in which order.
    """
    canvas = _Canvas(frame, scene.road)
    for item in scene.markings:
        canvas.fill(item.polygon, item.colour, item.roughness)
    for item in scene.ground:
        canvas.fill(item.polygon, item.colour, item.roughness)
    for car in scene.cars:
        if canvas.visible(car.body):
            canvas.fill(car.body, car.colour, 3)
            canvas.fill(car.cabin, _scaled(car.colour, 0.7), 3)

    _cast_shadows(canvas, scene)
    for b in scene.buildings:
        if canvas.visible(b.footprint) and b.facets:  # pitched: facets lit by the sun, textured shingles
            for facet, brightness in b.facets:
                canvas.fill(facet, _scaled(b.roof, brightness), 9)
            if b.ridge is not None:
                canvas.fill(b.ridge, _scaled(b.roof, 1.2), 4)
        elif canvas.visible(b.footprint):
            canvas.fill(b.footprint, b.roof, 6)
            if b.detail is not None:
                canvas.fill(b.detail, b.detail_colour, 6)
    _draw_trees(canvas, scene, rng)
    return _finish(canvas, rng, noise_sigma)


def _scaled(colour, factor: float) -> tuple[int, ...]:
    """A colour brightened or darkened by ``factor``, each band truncated to 0..255."""
    return tuple(int(np.clip(c * factor, 0, 255)) for c in colour)


def _cast_shadows(canvas: _Canvas, scene: Scene) -> None:
    """Darken the ground where buildings and crowns cast shadows (sun fixed per city)."""
    frame = canvas.frame
    shade = np.zeros(canvas.rough.shape, np.uint8)
    sx, sy = scene.sun
    for b in scene.buildings:
        if not canvas.visible(b.footprint.buffer(b.height * np.hypot(sx, sy) + 1.0)):
            continue
        base = np.asarray(b.footprint.exterior.coords)
        moved = base + np.array([sx, sy]) * b.height
        hull = cv2.convexHull(frame.to_pixels(np.concatenate([base, moved])))
        cv2.fillConvexPoly(shade, hull, 255, shift=SHIFT)
    for t in scene.trees:
        cx, cy = t.x + sx * t.radius * 1.5, t.y + sy * t.radius * 1.5
        p = frame.to_pixels(np.array([[cx, cy]]))[0]
        cv2.circle(shade, (int(p[0]), int(p[1])), int(t.radius / frame.gsd * SCALE), 255, -1, shift=SHIFT)
    shade = cv2.GaussianBlur(shade, (0, 0), 1.5)
    factor = 1.0 - 0.55 * (shade.astype(np.float32) / 255.0)
    canvas.image[:] = (canvas.image * factor[..., None]).astype(np.uint8)


def _draw_trees(canvas: _Canvas, scene: Scene, rng: np.random.Generator) -> None:
    """Crowns as clusters of overlapping discs of varied shade, rough in texture."""
    frame = canvas.frame
    x0, y0, x1, y1 = canvas.clip
    for t in scene.trees:
        if t.x + t.radius < x0 or t.x - t.radius > x1 or t.y + t.radius < y0 or t.y - t.radius > y1:
            continue
        local = np.random.default_rng(t.shape_seed)  # crown shape depends on the tree, not the tile
        if t.lobes != 5:
            _draw_lobed_crown(canvas, t, local, scene.sun)
            continue
        for k in range(5):
            r = t.radius * (0.55 if k else 0.85) * local.uniform(0.8, 1.1)
            off = local.uniform(-0.4, 0.4, 2) * t.radius if k else np.zeros(2)
            shade = local.uniform(0.8, 1.15)
            colour = _scaled(t.colour, shade)
            p = frame.to_pixels(np.array([[t.x + off[0], t.y + off[1]]]))[0]
            cv2.circle(canvas.image, (int(p[0]), int(p[1])), int(r / frame.gsd * SCALE), colour, -1, lineType=cv2.LINE_AA, shift=SHIFT)
            cv2.circle(canvas.rough, (int(p[0]), int(p[1])), int(r / frame.gsd * SCALE), 22, -1, shift=SHIFT)


def _draw_lobed_crown(canvas: _Canvas, t: Tree, local: np.random.Generator, sun: tuple[float, float]) -> None:
    """A crown of ``t.lobes`` small lobes over a dark core: lobes on the sun's side are lit, those
    away from it shaded, and the gaps between them stay dark, as a real canopy looks from above."""
    frame = canvas.frame
    norm = math.hypot(*sun)
    towards_sun = -np.asarray(sun, float) / norm if norm > 0 else np.zeros(2)
    discs = [(np.zeros(2), t.radius * 0.95, 0.6)]
    for _ in range(t.lobes):
        off = local.uniform(-0.62, 0.62, 2) * t.radius
        lit = float(np.dot(off, towards_sun)) / t.radius
        discs.append((off, t.radius * local.uniform(0.3, 0.5), local.uniform(0.8, 1.1) + 0.35 * lit))
    for off, r, shade in discs:
        p = frame.to_pixels(np.array([[t.x + off[0], t.y + off[1]]]))[0]
        centre, radius = (int(p[0]), int(p[1])), int(r / frame.gsd * SCALE)
        cv2.circle(canvas.image, centre, radius, _scaled(t.colour, shade), -1, lineType=cv2.LINE_AA, shift=SHIFT)
        cv2.circle(canvas.rough, centre, radius, 26, -1, shift=SHIFT)


def _finish(canvas: _Canvas, rng: np.random.Generator, noise_sigma: float) -> np.ndarray:
    """Texture, illumination, per-tile colour balance and sensor noise; returns (4, H, W) uint8."""
    size = canvas.frame.size
    texture = _smooth_noise(rng, size, 1.2) * canvas.rough.astype(np.float32)
    light = 1.0 + 0.07 * _smooth_noise(rng, size, size / 12)
    gains = rng.uniform(0.85, 1.12) * rng.uniform(0.94, 1.06, 4)
    out = np.empty((4, size, size), np.uint8)
    for band in range(4):
        plane = canvas.image[..., band].astype(np.float32)
        plane += texture
        plane *= light
        plane *= gains[band]
        plane += rng.standard_normal((size, size), dtype=np.float32) * noise_sigma
        np.clip(plane, 0, 255, out=plane)
        out[band] = plane
    return out


def _smooth_noise(rng: np.random.Generator, size: int, scale: float) -> np.ndarray:
    """Unit-variance noise with correlation length ~``scale`` px, by upsampling coarse noise."""
    coarse = max(2, int(round(size / max(scale, 1.0))))
    field = rng.standard_normal((coarse, coarse), dtype=np.float32)
    if coarse == size:
        return field
    return cv2.resize(field, (size, size), interpolation=cv2.INTER_CUBIC)


@dataclass(frozen=True)
class CameraLook:
    """How the sensor and the air change a city's pixels, drawn once per city.

    ``source_gsd`` is the sensor's pixel size: the tile is rendered at it and resampled to the
    city's pixel size (a coarse sensor upsampled looks soft, a fine one downsampled looks crisp).
    """

    source_gsd: float | None = None
    haze: float = 0.0
    saturation: float = 1.0
    gamma: float = 1.0
    gains: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)

    @property
    def is_identity(self) -> bool:
        return self.haze == 0 and self.saturation == 1 and self.gamma == 1 and self.gains == (1.0, 1.0, 1.0, 1.0)


HAZE_VEIL = np.array([196, 202, 212, 180], np.float32)  # a bright, slightly blue veil (NIR less)


def apply_look(image: np.ndarray, look: CameraLook) -> np.ndarray:
    """(4, H, W) uint8 -> same, with saturation, gamma, per-band gains and haze applied."""
    if look.is_identity:
        return image
    x = image.astype(np.float32)
    if look.saturation != 1:
        grey = x[:3].mean(axis=0, keepdims=True)
        x[:3] = grey + (x[:3] - grey) * look.saturation
    if look.gamma != 1:
        x = 255.0 * (np.clip(x, 0, 255) / 255.0) ** look.gamma
    x *= np.asarray(look.gains, np.float32)[:, None, None]
    if look.haze:
        x = x * (1 - look.haze) + HAZE_VEIL[:, None, None] * look.haze
    return np.clip(x, 0, 255).astype(np.uint8)


def resample(image: np.ndarray, size: int) -> np.ndarray:
    """(4, h, w) uint8 -> (4, size, size): area averaging when shrinking, cubic when enlarging."""
    if image.shape[1] == size:
        return image
    interpolation = cv2.INTER_AREA if image.shape[1] > size else cv2.INTER_CUBIC
    return np.stack([cv2.resize(band, (size, size), interpolation=interpolation) for band in image])
