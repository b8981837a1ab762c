"""Training samples drawn from synthetic (or imported) cities, labels computed on the fly.

Labels are cheap to compute for any window (see :mod:`csboundary.labels`), so samples are random
windows anywhere in a city, not fixed grid patches: more variety for the same imagery.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from csboundary.config import Config
from csboundary.data import city_layout
from csboundary.data.folder_lock import folder_lock
from csboundary.data.footprint import draw_window, union_area
from csboundary.data.ground_truth import read_complete_area, read_ground_truth, read_road_surface
from csboundary.data.raster import Mosaic
from csboundary.data.windows import PixelWindow
from csboundary.errors import InputError
from csboundary.labels.adjacency import adjacency_label
from csboundary.labels.config import LabelConfig
from csboundary.labels.patch_graph import window_graph
from csboundary.labels.writer import CityLabels
from csboundary.models.augmentation import (
    AugmentConfig,
    draw_geometry,
    paint_surface_negatives,
    photometric,
    source_side,
    warp,
)
from csboundary.models.augmentation import flip_rotate90 as augment  # also the baselines' flips
from csboundary.models.maps import unit_bands

NO_COMPLETE_AREA = "its complete area does not cover any of its imagery"


@dataclass(frozen=True)
class CitySpec:
    """A synthetic city by its recipe; built under ``cache`` on first use."""

    split: str = "train"
    seed: int = 0
    tiles: tuple[int, int] = (2, 2)
    tile_size: int = 5000
    style: str = "classic"  # csboundary.data.synth.styles.STYLES

    def path(self, cache: str | Path) -> Path:
        rows, cols = self.tiles
        style = "" if self.style == "classic" else f"{self.style}-"
        return Path(cache) / f"{self.split}-{style}s{self.seed}-{rows}x{cols}-{self.tile_size}"

    def ensure(self, cache: str | Path, progress: bool = True) -> Path:
        from csboundary.data.synth.city import synthesize_city
        from csboundary.data.synth.styles import style_config

        path = self.path(cache)
        if not city_layout.is_city_dir(path):
            path.mkdir(parents=True, exist_ok=True)
            with folder_lock(path, wait=True):  # a training building this city now: wait for it, then use its city
                if not city_layout.is_city_dir(path):
                    synthesize_city(
                        path,
                        self.seed,
                        self.split,
                        tuple(self.tiles),
                        style_config(self.style, tile_size=self.tile_size),
                        progress,
                    )
        return path


@dataclass(frozen=True)
class WorldsConfig(Config):
    """Many fresh synthetic cities to train on, their styles drawn from a configurable mix.

    City ``i`` is (split "train", seed ``first_seed + i``) in the style ``draw_style`` picks for
    it from ``styles`` (name -> weight), so the set is reproducible and a style left out of the
    mix is never seen; cities are built under the training cache on first use.
    """

    config_name = "worlds"

    styles: dict = field(default_factory=dict)  # style -> weight; {} = csboundary.data.synth.styles.DEFAULT_MIX
    cities: int = 24
    tiles: tuple[int, int] = (1, 1)
    tile_size: int = 2500
    first_seed: int = 1000

    def specs(self) -> list[CitySpec]:
        from csboundary.data.synth.styles import draw_style

        weights = self.styles or None
        return [
            CitySpec("train", seed, self.tiles, self.tile_size, draw_style("train", seed, weights))
            for seed in range(self.first_seed, self.first_seed + self.cities)
        ]


def _polygon_raster(polygons: list | None, mosaic: Mosaic) -> np.ndarray | None:
    """(H, W) uint8 over the whole city, 1 inside ``polygons`` (roadway, complete area), 0
    outside; None when the polygons are unknown."""
    if polygons is None:
        return None
    from rasterio.features import rasterize

    if not polygons:
        return np.zeros((mosaic.height, mosaic.width), np.uint8)
    return rasterize(
        polygons,
        out_shape=(mosaic.height, mosaic.width),
        transform=mosaic.transform,
        fill=0,
        default_value=1,
        dtype="uint8",
    )


def covers_imagery(polygons: list, mosaic: Mosaic) -> bool:
    """Whether ``polygons`` (in the mosaic's CRS) hold the centre of any pixel of the mosaic: a
    complete area that does not is refused by :class:`TrainingCity`. Only the polygons' bounding
    window is rasterized, as training rasterizes them."""
    from affine import Affine
    from rasterio.features import rasterize
    from shapely.ops import unary_union

    if not polygons:
        return False
    window = mosaic.window_from_bounds(*unary_union(polygons).bounds).intersection(mosaic.window)
    if window is None:
        return False
    transform = mosaic.transform @ Affine.translation(window.col_off, window.row_off)
    return bool(
        rasterize(
            polygons,
            out_shape=(window.height, window.width),
            transform=transform,
            fill=0,
            default_value=1,
            dtype="uint8",
        ).any()
    )


def city_probabilities(cities: list, extra: int, extra_share: float, by_area: bool) -> np.ndarray:
    """The probability of drawing each of ``cities`` for a sample, the last ``extra`` of them the
    extra (user) cities: within each group in proportion to area (``by_area``) or alike, the
    extra group as a whole ``extra_share`` of the draws (when both groups exist and it is > 0).
    The parts of one city (:meth:`TrainingCity.parts`) count as one city, and ``extra`` counts
    the extra cities' parts."""
    shared = Counter(c.path for c in cities)
    weights = np.array([union_area(c.mosaic.footprint) if by_area else 1 / shared[c.path] for c in cities], float)
    if extra_share <= 0 or not 0 < extra < len(cities):
        return weights / weights.sum()
    base, user = weights[:-extra], weights[-extra:]
    return np.concatenate([(1 - extra_share) * base / base.sum(), extra_share * user / user.sum()])


class TrainingCity:
    """A city's imagery and global label geometry, with samplers for both networks.

    A city whose ground truth has a ``complete_area`` layer (a reviewed prediction) is labelled
    only there: elsewhere every pixel is left out of the FPN's loss, its windows are drawn inside
    the area, and AfANet learns only from vertices inside it.
    """

    def __init__(self, city_dir: str | Path, config: LabelConfig = LabelConfig(), mosaic: Mosaic | None = None):
        self.path = Path(city_dir)
        # ``mosaic``: the city's imagery already open, or one group of its scattered tiles (:meth:`parts`)
        self.mosaic = mosaic if mosaic is not None else Mosaic.open(city_layout.tiles_dir(city_dir))
        gt = read_ground_truth(city_layout.ground_truth_path(city_dir), self.mosaic.crs)
        self.labels = CityLabels.build(list(gt.geometry), self.mosaic, config)
        self.surface = _polygon_raster(
            read_road_surface(city_layout.ground_truth_path(city_dir), self.mosaic.crs), self.mosaic
        )
        self.complete = _polygon_raster(
            read_complete_area(city_layout.ground_truth_path(city_dir), self.mosaic.crs), self.mosaic
        )
        if self.complete is not None and not self.complete.any():
            self.close()
            raise InputError(city_dir, NO_COMPLETE_AREA)
        self.config = config
        self.maps: np.ndarray | None = None  # (2, H, W) FPN probabilities, set before AfANet training

    @classmethod
    def parts(cls, city_dir: str | Path, config: LabelConfig = LabelConfig()) -> list["TrainingCity"]:
        """The city as training sees it: one TrainingCity, or, when its tiles lie apart (tiles
        scattered over a city, data/footprint.py), one per group of touching tiles, so that no
        raster of the city (complete area, road surface, AfANet's maps) spans the gaps. A group
        that the complete area misses is left out; the city is refused when all are."""
        whole = Mosaic.open(city_layout.tiles_dir(city_dir))  # opened once: each group is a crop of it
        if len(whole.footprint) == 1:
            return [cls(city_dir, config, whole)]
        found, refused = [], None
        try:
            for box in whole.footprint:
                try:
                    found.append(cls(city_dir, config, whole.crop(box)))
                except InputError as exc:
                    if not exc.problem.startswith(NO_COMPLETE_AREA):
                        for part in found:
                            part.close()
                        raise
                    refused = exc  # the reviewer marked nothing complete in this group: nothing known to learn there
        finally:
            whole.close()  # the crops open their own files
        if not found:
            raise refused
        return found

    def close(self) -> None:
        """Close the imagery's files (a training run closes its cities when it ends)."""
        self.mosaic.close()

    def __enter__(self) -> "TrainingCity":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def random_window(self, rng: np.random.Generator, size: int) -> PixelWindow:
        """A ``size`` square anywhere the city's imagery lies, all places alike; in a partly labelled city, one
        whose centre lies in its complete area (drawn the same way and kept when it does, so a city
        complete everywhere samples as a fully labelled one)."""
        for _ in range(1 if self.complete is None else 100):
            window = draw_window(rng, self.mosaic.footprint, size)
            if self.complete is None or self._complete_at(window.col_off + size // 2, window.row_off + size // 2):
                return window
        rows, cols = np.nonzero(self.complete[::8, ::8])  # a small area: centre the window on one of its pixels
        k = int(rng.integers(len(rows)))
        col = int(
            np.clip(int(cols[k]) * 8 - size // 2, min(0, self.mosaic.width - size), max(0, self.mosaic.width - size))
        )
        row = int(
            np.clip(int(rows[k]) * 8 - size // 2, min(0, self.mosaic.height - size), max(0, self.mosaic.height - size))
        )
        return PixelWindow(col, row, size, size)

    def _complete_at(self, col: int, row: int) -> bool:
        return 0 <= row < self.complete.shape[0] and 0 <= col < self.complete.shape[1] and bool(self.complete[row, col])

    def _cut(self, raster: np.ndarray, window: PixelWindow, fill, dtype) -> np.ndarray:
        """``raster`` (..., H, W) over the whole city, cut to ``window``; ``fill`` outside the city."""
        out = np.full((*raster.shape[:-2], window.height, window.width), fill, dtype)
        part = window.intersection(self.mosaic.window)
        if part is not None:
            rows, cols = part.slices()
            lrows, lcols = part.relative_to(window).slices()
            out[..., lrows, lcols] = raster[..., rows, cols]
        return out

    def known(self, window: PixelWindow) -> np.ndarray:
        """(s, s) bool: where the window's labels are known (inside the city and its complete area)."""
        inside = (
            np.broadcast_to(np.True_, (self.mosaic.height, self.mosaic.width))
            if self.complete is None
            else self.complete
        )
        return self._cut(inside, window, False, bool)

    def fpn_sample(self, window: PixelWindow, surface: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Image (4, s, s) float32 in [0, 1]; targets (2, s, s): keypoint heat, segmentation, with
        ``surface`` a third channel, the road surface (1 roadway, 0 not, -1 unknown); valid (s, s)."""
        read = self.mosaic.read(window)
        targets = self.labels.network_targets(window)
        if surface:
            targets = np.concatenate([targets, self.surface_target(window)[None]])
        valid = read.valid if self.complete is None else read.valid & self.known(window)
        return unit_bands(read.data), targets, valid

    def surface_target(self, window: PixelWindow) -> np.ndarray:
        """(s, s) float32 road surface of a window: 1 roadway, 0 not, -1 where unknown (a city
        without a ``road_surface`` layer, or outside the city)."""
        if self.surface is None:
            return np.full((window.height, window.width), -1.0, np.float32)
        return self._cut(self.surface, window, -1.0, np.float32)

    def augmented_fpn_sample(
        self, rng: np.random.Generator, crop: int, config: AugmentConfig, surface: bool = False
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``fpn_sample`` of a random ``crop`` window, rotated by any angle, scaled, flipped and
        re-lit (see :mod:`csboundary.models.augmentation`): the source window is read large
        enough that the rotated crop holds imagery wherever the city does. With a road surface and
        ``config.surface_negatives``, foreign clutter is painted over part of its non-road area
        before the re-lighting (:func:`~csboundary.models.augmentation.paint_surface_negatives`)."""
        angle, scale = draw_geometry(rng, config)
        side = source_side(crop, angle, scale) if (angle or scale != 1) else crop
        image, target, valid = self.fpn_sample(self.random_window(rng, side), surface)
        if side != crop:
            road = warp(target[2:3] + 1, angle, scale, crop, nearest=True)[0] - 1 if surface else None
            image, target = warp(image, angle, scale, crop), warp(target, angle, scale, crop)
            if surface:  # nearest: an unknown (-1) surface must not blend into a known one
                target[2] = road
            valid = warp(valid.astype(np.uint8), angle, scale, crop, nearest=True).astype(bool)
        image, target, valid = augment(rng, image, target, valid)
        image = paint_surface_negatives(rng, image, target, valid, config)  # off by default: no random draw
        return photometric(rng, image, config), target, valid

    def gt_vertices(self, window: PixelWindow) -> np.ndarray:
        """Ground-truth keypoints inside ``window`` as global pixel coordinates (M, 2)."""
        graph, _ = window_graph(self.labels.keypoints, self.labels.bounds, window)
        return graph.vertices + np.array([window.col_off, window.row_off])

    def afanet_tensor(self, window: PixelWindow) -> np.ndarray:
        """The 6-channel input of AfANet: image bands and the FPN probability maps, (6, s, s)."""
        if self.maps is None:
            raise RuntimeError("predict the city's FPN maps before sampling AfANet inputs")
        read = self.mosaic.read(window)
        maps = self._cut(self.maps[:2], window, 0.0, np.float32)  # AfANet reads keypoints and boundary, not the surface
        return np.concatenate([unit_bands(read.data), maps])

    def labelled(self, vertices: np.ndarray) -> np.ndarray:
        """(M,) bool: which vertices (global pixel coordinates) lie where the labels are known."""
        if self.complete is None:
            return np.ones(len(vertices), bool)
        col, row = np.floor(vertices[:, 0]).astype(int), np.floor(vertices[:, 1]).astype(int)
        inside = (col >= 0) & (row >= 0) & (col < self.mosaic.width) & (row < self.mosaic.height)
        out = np.zeros(len(vertices), bool)
        out[inside] = self.complete[row[inside], col[inside]] > 0
        return out

    def adjacency(self, vertices: np.ndarray, window: PixelWindow) -> np.ndarray:
        lab = self.labels
        return adjacency_label(vertices, lab.boundaries, lab.bounds, window, self.config.snap_tolerance_px)
