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
import shapely.affinity
from shapely.geometry import Polygon

from csboundary.data.synth.scene import ASPHALT, WINDOW, Scene, Tree

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


class Canvas:
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
    canvas = Canvas(frame, scene.road)
    for item in scene.markings:
        canvas.fill(item.polygon, item.colour, item.roughness)
    for item in scene.ground:
        canvas.fill(item.polygon, item.colour, item.roughness)
    if any(car.detail for car in scene.cars):
        _car_shadows(canvas, scene)
    for car in scene.cars:
        if canvas.visible(car.body) and car.detail:
            draw_detailed_car(canvas, car)
        elif canvas.visible(car.body):
            canvas.fill(car.body, car.colour, 3)
            canvas.fill(car.cabin, _scaled(car.colour, 0.7), 3)

    _cast_shadows(canvas, scene)
    if scene.lean != (0.0, 0.0):
        _draw_leaning_buildings(canvas, scene)
    else:
        for b in scene.buildings:
            if canvas.visible(b.footprint):
                _draw_roof(canvas, b)
    _draw_trees(canvas, scene, rng)
    return _finish(canvas, rng, noise_sigma, scene.texture)


def _draw_roof(canvas: Canvas, b, shift: tuple[float, float] = (0.0, 0.0)) -> None:
    """A building's roof moved by ``shift`` metres: pitched facets lit by the sun (textured
    shingles) and a ridge, or a flat roof with its structure, parapet rim and rooftop items."""
    move = (lambda g: shapely.affinity.translate(g, *shift)) if shift != (0.0, 0.0) else (lambda g: g)
    if b.facets:
        for facet, brightness in b.facets:
            canvas.fill(move(facet), _scaled(b.roof, brightness), 9)
        if b.ridge is not None:
            canvas.fill(move(b.ridge), _scaled(b.roof, 1.2), 4)
        return
    canvas.fill(move(b.footprint), b.roof, 6)
    if b.detail is not None:
        canvas.fill(move(b.detail), b.detail_colour, 6)
    if b.parapet is not None:  # ``flat_roof_detail``
        rim = b.footprint.difference(b.footprint.buffer(-b.parapet_width, join_style="mitre"))
        canvas.fill(move(rim), b.parapet, 4)
        for item, colour in b.roof_items:
            canvas.fill(move(item), colour, 5)


def _draw_leaning_buildings(canvas: Canvas, scene: Scene) -> None:
    """Relief displacement: every roof drawn ``lean * height`` metres from its footprint, over
    the facade strip between them (the wall seen at an angle). Facades first, then roofs, so an
    attached neighbour's roof covers the wall it leans over. Roof pixels only; the ground truth
    never moves."""
    lx, ly = scene.lean
    shown = []
    for b in scene.buildings:
        shift = (lx * b.height, ly * b.height)
        if not canvas.visible(b.footprint.buffer(math.hypot(*shift) + 1.0)):
            continue
        shown.append((b, shift))
        base = np.asarray(b.footprint.exterior.coords)
        hull = shapely.convex_hull(shapely.MultiPoint(np.concatenate([base, base + np.asarray(shift)])))
        canvas.fill(hull, (96, 80, 70, 80), 8)  # the wall seen at an angle: brick and shade
    for b, shift in shown:
        _draw_roof(canvas, b, shift)


def _car_axes(car) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Centre, unit front direction, unit side direction, length and width of a car's body."""
    c = np.asarray(car.body.exterior.coords)[:4]
    along, across = c[1] - c[0], c[3] - c[0]
    length, width = float(np.linalg.norm(along)), float(np.linalg.norm(across))
    return c.mean(axis=0), along / length, across / width, length, width


def _band(centre, along, across, a0: float, a1: float, width: float) -> Polygon:
    """The part of a car between fractions ``a0`` and ``a1`` of its length (0 = rear), ``width`` wide."""
    return Polygon(
        [
            centre + along * a0 - across * width / 2,
            centre + along * a1 - across * width / 2,
            centre + along * a1 + across * width / 2,
            centre + along * a0 + across * width / 2,
        ]
    )


def draw_detailed_car(canvas: Canvas, car) -> None:
    """A car from above: a darker rim, dark windshield and rear window, a lit roof between them."""
    c, along, across, length, width = _car_axes(car)
    rear = c - along * length / 2
    canvas.fill(car.body, _scaled(car.colour, 0.78), 3)
    canvas.fill(car.body.buffer(-0.12, join_style="round"), car.colour, 3)
    if length > 5.8:  # vans and trucks: a long flat roof, a windshield at the front only
        canvas.fill(_band(rear, along, across, 0.05 * length, 0.8 * length, width * 0.9), _scaled(car.colour, 1.08), 2)
        canvas.fill(_band(rear, along, across, 0.8 * length, 0.88 * length, width * 0.86), WINDOW, 2)
        return
    canvas.fill(_band(rear, along, across, 0.14 * length, 0.27 * length, width * 0.78), WINDOW, 2)
    canvas.fill(_band(rear, along, across, 0.27 * length, 0.56 * length, width * 0.74), _scaled(car.colour, 1.12), 2)
    canvas.fill(_band(rear, along, across, 0.34 * length, 0.5 * length, width * 0.4), _scaled(car.colour, 1.22), 2)
    canvas.fill(_band(rear, along, across, 0.56 * length, 0.72 * length, width * 0.8), WINDOW, 2)


def _car_shadows(canvas: Canvas, scene: Scene) -> None:
    """Short shadows of detailed cars (1.5 m tall) on the ground away from the sun."""
    frame = canvas.frame
    shade = np.zeros(canvas.rough.shape, np.uint8)
    sx, sy = scene.sun
    for car in scene.cars:
        if not car.detail or not canvas.visible(car.body.buffer(3.0)):
            continue
        base = np.asarray(car.body.exterior.coords)
        hull = cv2.convexHull(frame.to_pixels(np.concatenate([base, base + np.array([sx, sy]) * 1.5])))
        cv2.fillConvexPoly(shade, hull, 255, shift=SHIFT)
    shade = cv2.GaussianBlur(shade, (0, 0), 1.0)
    factor = 1.0 - 0.5 * (shade.astype(np.float32) / 255.0)
    canvas.image[:] = (canvas.image * factor[..., None]).astype(np.uint8)


def _scaled(colour, factor: float) -> tuple[int, ...]:
    """A colour brightened or darkened by ``factor``, each band truncated to 0..255."""
    return tuple(int(np.clip(c * factor, 0, 255)) for c in colour)


def _cast_shadows(canvas: Canvas, scene: Scene) -> None:
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
        if t.bare:  # leafless crowns cast a faint web, not a disc
            continue
        cx, cy = t.x + sx * t.radius * 1.5, t.y + sy * t.radius * 1.5
        p = frame.to_pixels(np.array([[cx, cy]]))[0]
        cv2.circle(shade, (int(p[0]), int(p[1])), int(t.radius / frame.gsd * SCALE), 255, -1, shift=SHIFT)
    shade = cv2.GaussianBlur(shade, (0, 0), 1.5)
    factor = 1.0 - 0.55 * (shade.astype(np.float32) / 255.0)
    canvas.image[:] = (canvas.image * factor[..., None]).astype(np.uint8)


def _draw_trees(canvas: Canvas, scene: Scene, rng: np.random.Generator) -> None:
    """Crowns as clusters of overlapping discs of varied shade, rough in texture."""
    frame = canvas.frame
    x0, y0, x1, y1 = canvas.clip
    for t in scene.trees:
        if t.x + t.radius < x0 or t.x - t.radius > x1 or t.y + t.radius < y0 or t.y - t.radius > y1:
            continue
        local = np.random.default_rng(t.shape_seed)  # crown shape depends on the tree, not the tile
        if t.bare:
            _draw_bare_crown(canvas, t, local)
            continue
        if t.lobes != 5:
            draw_lobed_crown(canvas, t, local, scene.sun)
            continue
        for k in range(5):
            r = t.radius * (0.55 if k else 0.85) * local.uniform(0.8, 1.1)
            off = local.uniform(-0.4, 0.4, 2) * t.radius if k else np.zeros(2)
            shade = local.uniform(0.8, 1.15)
            colour = _scaled(t.colour, shade)
            p = frame.to_pixels(np.array([[t.x + off[0], t.y + off[1]]]))[0]
            cv2.circle(
                canvas.image,
                (int(p[0]), int(p[1])),
                int(r / frame.gsd * SCALE),
                colour,
                -1,
                lineType=cv2.LINE_AA,
                shift=SHIFT,
            )
            cv2.circle(canvas.rough, (int(p[0]), int(p[1])), int(r / frame.gsd * SCALE), 22, -1, shift=SHIFT)


def _draw_bare_crown(canvas: Canvas, t: Tree, local: np.random.Generator) -> None:
    """A leafless crown: the ground seen through a grey-brown veil, dark branches radiating from
    the trunk and forking (spring imagery of a dense city)."""
    frame = canvas.frame
    r_px = t.radius / frame.gsd
    c = frame.to_pixels(np.array([[t.x, t.y]]))[0] / SCALE
    x0, y0 = int(max(c[0] - r_px - 2, 0)), int(max(c[1] - r_px - 2, 0))
    x1, y1 = int(min(c[0] + r_px + 3, frame.size)), int(min(c[1] + r_px + 3, frame.size))
    if x1 <= x0 or y1 <= y0:
        return
    mask = np.zeros((y1 - y0, x1 - x0), np.float32)
    centre = (c[0] - x0, c[1] - y0)
    cv2.circle(
        mask,
        (int(centre[0] * SCALE), int(centre[1] * SCALE)),
        int(r_px * SCALE),
        0.35,
        -1,
        lineType=cv2.LINE_AA,
        shift=SHIFT,
    )
    for _ in range(int(local.integers(7, 13))):
        angle, reach = local.uniform(0, 2 * math.pi), local.uniform(0.6, 1.0) * r_px
        end = (centre[0] + reach * math.cos(angle), centre[1] + reach * math.sin(angle))
        pts = [centre, end]
        for _ in range(2):  # two forks near the tip
            a2 = angle + local.uniform(-0.7, 0.7)
            mid = (centre[0] + 0.55 * reach * math.cos(angle), centre[1] + 0.55 * reach * math.sin(angle))
            pts.append(mid)
            pts.append((mid[0] + 0.45 * reach * math.cos(a2), mid[1] + 0.45 * reach * math.sin(a2)))
        for a, b in zip(pts[0::2], pts[1::2]):
            cv2.line(
                mask,
                (int(a[0] * SCALE), int(a[1] * SCALE)),
                (int(b[0] * SCALE), int(b[1] * SCALE)),
                0.8,
                max(1, int(0.12 / frame.gsd)),
                lineType=cv2.LINE_AA,
                shift=SHIFT,
            )
    mask = cv2.GaussianBlur(mask, (0, 0), max(0.6, 0.08 / frame.gsd))[..., None]
    roi = canvas.image[y0:y1, x0:x1].astype(np.float32)
    colour = np.asarray(t.colour, np.float32)
    canvas.image[y0:y1, x0:x1] = (roi * (1 - mask) + colour * mask).astype(np.uint8)
    canvas.rough[y0:y1, x0:x1] = np.maximum(canvas.rough[y0:y1, x0:x1], (mask[..., 0] > 0.3) * 14).astype(np.uint8)


def draw_lobed_crown(canvas: Canvas, t: Tree, local: np.random.Generator, sun: tuple[float, float]) -> None:
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


def _finish(canvas: Canvas, rng: np.random.Generator, noise_sigma: float, photo_texture: float = 0.0) -> np.ndarray:
    """Texture, illumination, per-tile colour balance and sensor noise; returns (4, H, W) uint8."""
    size = canvas.frame.size
    texture = _smooth_noise(rng, size, 1.2) * canvas.rough.astype(np.float32)
    if photo_texture > 0:
        texture += _photo_texture(canvas, rng, photo_texture)
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


def _photo_texture(canvas: Canvas, rng: np.random.Generator, amplitude: float) -> np.ndarray:
    """Texture at every scale (``photo_texture``): stains and blotches of 1-20 m, a grain of a
    few pixels and sparse gravel specks, strongest on rough ground and roofs, weak on cars and
    paint. Pixel scales are those of the frame (metres / gsd), so a coarse sensor sees the same."""
    size, gsd = canvas.frame.size, canvas.frame.gsd
    weight = np.minimum(canvas.rough, 10).astype(np.float32) / 6.0
    field = (
        0.9 * _smooth_noise(rng, size, 18.0 / gsd)
        + 0.7 * _smooth_noise(rng, size, 5.0 / gsd)
        + 0.5 * _smooth_noise(rng, size, 1.2 / gsd)
        + 0.35 * _smooth_noise(rng, size, 0.45 / gsd)
    )
    speck = rng.random((size, size), dtype=np.float32)
    field += np.where(speck < 0.015, 3.0, 0.0) - np.where(speck > 0.985, 3.0, 0.0)
    return field * weight * amplitude


def _smooth_noise(rng: np.random.Generator, size: int, scale: float) -> np.ndarray:
    """Unit-variance noise with correlation length ~``scale`` px, by upsampling coarse noise."""
    coarse = max(2, int(round(size / max(scale, 1.0))))
    field = rng.standard_normal((coarse, coarse), dtype=np.float32)
    if coarse == size:
        return field
    return cv2.resize(field, (size, size), interpolation=cv2.INTER_CUBIC)
