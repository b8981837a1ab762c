"""Synthesize a whole city: street network and scene once, then every tile, then ground truth.

A city is a function of (config, split, seed, tiles): the same arguments give the same bytes.
It is designed and rendered in metres on the ground (``gsd`` is metres per pixel), then placed in
its CRS through that CRS's units at the origin, so a city in US feet or degrees has the same
pixels on the same ground as one in UTM metres.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace
from functools import cached_property
from pathlib import Path

import geopandas as gpd
import numpy as np
import shapely
from affine import Affine
from tqdm import tqdm

from csboundary import __version__
from csboundary.data import city_layout
from csboundary.data.folder_lock import locked_folder
from csboundary.data.geotiff import write_geotiff
from csboundary.data.ground_truth import write_ground_truth
from csboundary.data.synth.camera import CameraLook, apply_look, resample
from csboundary.data.synth.config import SynthConfig, city_rng
from csboundary.data.synth.render import TileFrame, render_tile
from csboundary.data.synth.scene import Scene, build_scene
from csboundary.data.synth.streets import build_network
from csboundary.data.units import GroundUnits, ground_units


@dataclass
class SyntheticCity:
    """The geometry of a city before rendering: its scene (network inside) and tile city_layout."""

    config: SynthConfig
    split: str
    seed: int
    tiles: tuple[int, int]
    scene: Scene
    look: CameraLook = CameraLook()

    @property
    def size_m(self) -> tuple[float, float]:
        rows, cols = self.tiles
        side = self.config.tile_size * self.config.gsd
        return cols * side, rows * side

    def frame(self, row: int, col: int) -> TileFrame:
        """Local-metre frame of tile (row, col); row 0 is the northernmost."""
        side = self.config.tile_size * self.config.gsd
        return TileFrame(x0=col * side, y1=self.size_m[1] - row * side, size=self.config.tile_size, gsd=self.config.gsd)

    @cached_property
    def units(self) -> GroundUnits:
        """The CRS's units at the city's origin: the city is laid out in metres, its CRS may count
        feet or degrees, so every world coordinate is converted through them."""
        return crs_units(self.config)

    def to_world(self, geometry):
        """A geometry in local metres (origin at the city's south-west corner) in the city's CRS."""
        scale = np.asarray(self.units.metres_per_unit)  # 1.0 in a metre CRS: the coordinates are unchanged, bit for bit
        shift = np.asarray((self.config.origin_x, self.config.origin_y))
        return shapely.transform(geometry, lambda xy: xy / scale + shift)

    def transform(self, row: int, col: int) -> Affine:
        """World transform of tile (row, col) in the city's CRS: ``gsd`` metres per pixel on the
        ground, whatever unit the CRS counts in."""
        f = self.frame(row, col)
        east, north = self.units.metres_per_unit
        return Affine(
            f.gsd / east,
            0.0,
            self.config.origin_x + f.x0 / east,
            0.0,
            -f.gsd / north,
            self.config.origin_y + f.y1 / north,
        )

    def ground_truth(self) -> gpd.GeoDataFrame:
        """Road boundaries in world coordinates, one LineString per row, with kind and closedness."""
        lines = [self.to_world(line) for line, _ in self.scene.network.boundaries]
        kinds = [kind for _, kind in self.scene.network.boundaries]
        return gpd.GeoDataFrame(
            {"kind": kinds, "closed": [bool(line.is_closed) for line in lines]}, geometry=lines, crs=self.config.crs
        )

    def road_surface(self) -> gpd.GeoDataFrame:
        """The roadway (islands and medians cut out) clipped to the city, in world coordinates:
        the FPN's road-surface target."""
        width, height = self.size_m
        roadway = shapely.clip_by_rect(self.scene.network.roadway, 0.0, 0.0, width, height)
        parts = [p for p in getattr(roadway, "geoms", [roadway]) if p.geom_type == "Polygon" and not p.is_empty]
        return gpd.GeoDataFrame(geometry=[self.to_world(p) for p in parts], crs=self.config.crs)

    def render(self, row: int, col: int) -> np.ndarray:
        rng = city_rng(self.split, self.seed, 1, row, col)
        frame = self.frame(row, col)
        if self.look.source_gsd is not None:  # render at the sensor's pixel size, then resample
            size = max(1, round(frame.size * frame.gsd / self.look.source_gsd))
            sensor = TileFrame(frame.x0, frame.y1, size, frame.size * frame.gsd / size)
            image = resample(render_tile(self.scene, sensor, rng, self.config.noise_sigma), frame.size)
        else:
            image = render_tile(self.scene, frame, rng, self.config.noise_sigma)
        return apply_look(image, self.look)


def crs_units(config: SynthConfig) -> GroundUnits:
    """The units of ``config.crs`` at its origin; ValueError for a CRS pyproj does not know or an
    origin that is no place in it (degrees beyond the globe: an origin left in UTM metres)."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        crs = CRS.from_user_input(config.crs)
    except CRSError as exc:
        raise ValueError(f"unknown CRS {config.crs!r}") from exc
    if crs.is_geographic and not (abs(config.origin_x) <= 180 and abs(config.origin_y) < 90):
        raise ValueError(
            f"origin ({config.origin_x:g}, {config.origin_y:g}) is no place in the geographic CRS {config.crs}"
        )
    return ground_units(crs, (config.origin_x, config.origin_y))


def in_crs(config: SynthConfig, crs: str) -> SynthConfig:
    """``config`` placed in ``crs``: the origin moved to the same place on the ground (New York
    for the default), so the city is the same, only counted in another CRS's units."""
    from pyproj import CRS, Transformer
    from pyproj.exceptions import CRSError, ProjError

    try:
        target = CRS.from_user_input(crs)
        x, y = Transformer.from_crs(config.crs, target, always_xy=True).transform(
            config.origin_x, config.origin_y, errcheck=True
        )
    except (CRSError, ProjError) as exc:
        raise ValueError(
            f"cannot place the city in {crs!r} ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
        ) from exc
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"the city's place has no coordinates in {crs!r}")
    name = f"{target.to_authority()[0]}:{target.to_authority()[1]}" if target.to_authority() else target.to_wkt()
    return replace(config, crs=name, origin_x=float(x), origin_y=float(y))


def draw_look(config: SynthConfig, split: str, seed: int) -> CameraLook:
    """The city's camera look, from its own random stream (the default config draws nothing)."""
    rng = city_rng(split, seed, 2)
    source = float(rng.uniform(*config.source_gsd)) if config.source_gsd is not None else None
    cast = config.colour_cast
    haze = float(rng.uniform(*config.haze))
    saturation = float(rng.uniform(*config.saturation))
    gamma = float(rng.uniform(*config.gamma))
    gains = tuple(float(g) for g in (rng.uniform(1 - cast, 1 + cast, 4) if cast else np.ones(4)))
    # drawn after the older fields and only when switched on, so older looks stay the same
    blur = float(rng.uniform(*config.photo_blur)) if config.photo_blur[1] > 0 else 0.0
    jpeg = int(rng.integers(config.jpeg_quality[0], config.jpeg_quality[1] + 1)) if config.jpeg_quality[1] > 0 else 0
    # type: ignore[arg-type]
    return CameraLook(
        source_gsd=source, haze=haze, saturation=saturation, gamma=gamma, gains=gains, blur=blur, jpeg=jpeg
    )


def plan_city(config: SynthConfig, split: str, seed: int, tiles: tuple[int, int]) -> SyntheticCity:
    """Build the street network and scene of a city (no pixels yet)."""
    rows, cols = tiles
    if rows < 1 or cols < 1:
        raise ValueError(f"tiles must be at least 1x1, got {rows}x{cols}")
    rng = city_rng(split, seed, 0)
    crs_units(config)  # a CRS the city cannot be placed in is refused before any work
    side = config.tile_size * config.gsd
    network = build_network(config, rng, cols * side, rows * side)
    scene = build_scene(config, rng, network)
    return SyntheticCity(config, split, seed, tiles, scene, draw_look(config, split, seed))


def synthesize_city(
    out_dir: str | Path,
    seed: int,
    split: str,
    tiles: tuple[int, int] = (1, 1),
    config: SynthConfig = SynthConfig(),
    progress: bool = True,
) -> dict:
    """Write a city directory (tiles, ground truth, city.json) and return its metadata.

    ``city.json`` is written last: a directory without it is an interrupted run, not a city.
    Two runs writing one city at once (two trainings building the same cache city) are one run
    and a one-line refusal (data/folder_lock.py).
    """
    with locked_folder(out_dir, "OUT"):
        return _synthesize_city(out_dir, seed, split, tiles, config, progress)


def _synthesize_city(
    out_dir: str | Path, seed: int, split: str, tiles: tuple[int, int], config: SynthConfig, progress: bool
) -> dict:
    out_dir = city_layout.begin_city(out_dir)
    start = time.perf_counter()
    city = plan_city(config, split, seed, tiles)
    planned = time.perf_counter() - start
    rows, cols = tiles
    records, render_seconds = [], []
    for row, col in tqdm(
        [(r, c) for r in range(rows) for c in range(cols)], desc="render tiles", unit="tile", disable=not progress
    ):
        t0 = time.perf_counter()
        image = city.render(row, col)
        render_seconds.append(time.perf_counter() - t0)
        name = city_layout.tile_name(row, col)
        write_geotiff(
            city_layout.tiles_dir(out_dir) / name,
            image,
            city.transform(row, col),
            config.crs,
            tags={
                "generator": f"csboundary {__version__} synth",
                "split": split,
                "seed": str(seed),
                "tile_row": str(row),
                "tile_col": str(col),
            },
        )
        records.append({"path": f"{city_layout.TILES_DIR}/{name}", "row": row, "col": col})
    gt = city.ground_truth()
    write_ground_truth(city_layout.ground_truth_path(out_dir), gt, city.road_surface())
    meta = {
        "source": "synthetic",
        "generator": f"csboundary {__version__}",
        "style": config.style,
        "look": asdict(city.look),
        "split": split,
        "seed": seed,
        "tiles": records,
        "tile_grid": [rows, cols],
        "crs": config.crs,
        "gsd": config.gsd / city.units.metres_per_unit[0],  # CRS units, as every city.json's
        "units": city.units.unit_name,
        "pixel_m": config.gsd,  # metres: --gsd
        "config": config.to_dict(),
        "counts": {
            "boundaries": len(gt),
            "boundary_km": round(
                sum(line.length for line, _ in city.scene.network.boundaries) / 1000, 3
            ),  # metres, in any CRS
            "blocks": len(city.scene.network.blocks),
            "islands": len(city.scene.network.islands),
            "medians": len(city.scene.network.medians),
            "buildings": len(city.scene.buildings),
            "trees": len(city.scene.trees),
            "cars": len(city.scene.cars),
        },
        "seconds": {"plan": round(planned, 2), "render_per_tile": [round(s, 2) for s in render_seconds]},
    }
    city_layout.write_meta(out_dir, meta)
    return meta
