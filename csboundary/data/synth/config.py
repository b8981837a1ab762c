"""Parameters of the synthetic city, with defaults chosen to resemble the NYC benchmark.

Lengths are metres unless named ``*_px``. The reference patch (shared/reference) shows streets
of ~100 px (15 m at 0.152 m/px), curb returns of ~30-40 px radius, parked cars and trees on the
curb, crosswalks and lane markings; the defaults below reproduce those proportions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csboundary.config import Config

SPLITS = ("train", "valid", "test")


@dataclass(frozen=True)
class SynthConfig(Config):
    """Everything that shapes one synthetic city. All fields are plain numbers, so a config is
    recorded in ``city.json`` and a city is reproduced from (config, split, seed)."""

    config_name = "synth"

    # raster
    tile_size: int = 5000  # px per tile side
    gsd: float = 0.152  # metres per pixel on the ground (NYC: 0.5 ft), in any CRS
    crs: str = "EPSG:32618"  # WGS 84 / UTM 18N (New York), metres; another (feet, degrees): city.in_crs
    origin_x: float = 583000.0  # world x of the city's west edge, in the CRS's units
    origin_y: float = 4507000.0  # world y of the city's south edge, in the CRS's units
    # street network
    avenue_spacing: tuple[float, float] = (130.0, 240.0)
    street_spacing: tuple[float, float] = (60.0, 110.0)
    avenue_width: tuple[float, float] = (13.0, 20.0)  # roadway width, curb to curb
    street_width: tuple[float, float] = (8.5, 13.0)
    cross_street_skew_deg: float = 8.0  # cross streets deviate from perpendicular by up to this
    boulevard_share: float = 0.3  # avenues with a median
    median_width: tuple[float, float] = (2.0, 5.0)
    boulevard_extra_width: tuple[float, float] = (6.0, 10.0)
    curved_street_share: float = 0.25  # cross streets replaced by a gently curving one
    curve_amplitude: tuple[float, float] = (8.0, 25.0)
    diagonals_per_km2: float = 0.5
    dropped_segment_share: float = 0.08  # cross-street segments removed (merged blocks)
    dead_end_share: float = 0.12  # cross-street segments cut to a dead end
    cul_de_sac_share: float = 0.5  # dead ends that end in a round bulb
    island_share: float = 0.15  # intersections that get a traffic island
    curb_radius: tuple[float, float] = (3.0, 12.0)  # curb-return radius per block
    sharp_block_share: float = 0.15  # blocks whose corners stay sharp
    margin: float = 60.0  # streets are built this far beyond the city so edges look like the inside
    # what stands on and beside the road
    sidewalk_width: tuple[float, float] = (2.5, 5.0)
    park_share: float = 0.1
    lot_share: float = 0.15  # commercial blocks with asphalt parking lots
    street_tree_spacing: tuple[float, float] = (7.0, 14.0)
    street_tree_radius: tuple[float, float] = (2.0, 5.0)
    parked_car_spacing: float = 6.2
    parked_car_occupancy: tuple[float, float] = (0.3, 0.85)
    moving_cars_per_km: float = 25.0
    driveway_spacing: tuple[float, float] = (15.0, 45.0)
    crosswalk_share: float = 0.6
    # appearance
    noise_sigma: float = 5.0  # per-pixel sensor noise, digital numbers
    # ---- style knobs (csboundary/data/synth/styles.py); the defaults reproduce the original
    # grid city byte for byte, so every knob draws random numbers only when it is switched on.
    style: str = "classic"  # the style this config was built from (recorded in city.json)
    layout: str = "grid"  # grid | suburb (collectors + curvy local streets, T-junctions, cul-de-sacs)
    bearing_deg: tuple[float, float] = (-35.0, 35.0)  # range of the grid's bearing
    avenue_curve_share: float = 0.0  # avenues that curve like the curved cross streets
    roundabout_share: float = 0.0  # crossings of two streets turned into a roundabout
    roundabout_radius: tuple[float, float] = (13.0, 20.0)  # outer radius of the ring road
    bulb_island_share: float = 0.0  # cul-de-sac bulbs (radius >= 8 m) with a planted centre island
    branch_spacing: tuple[float, float] = (70.0, 140.0)  # suburb: local streets along a collector
    branch_length: tuple[float, float] = (60.0, 160.0)  # suburb: local street length
    loop_share: float = 0.3  # suburb: local streets that come back to their collector (a crescent)
    highways: int = 0  # motorways across the city (a median, no crossing but the avenues)
    highway_angle_deg: tuple[float, float] = (15.0, 75.0)  # a highway's angle to the avenues
    highway_carriageway: tuple[float, float] = (10.0, 15.0)  # one direction's roadway, curb to median
    highway_median: tuple[float, float] = (3.0, 12.0)
    highway_frontage: float = 35.0  # streets other than avenues end this far from a highway's edge
    ramp_share: float = 1.0  # avenue crossings of a highway that get a diamond of four ramps
    ramp_width: tuple[float, float] = (5.5, 8.0)
    raised_curb: bool = True  # False: rural edge, asphalt straight onto a shoulder and verge
    shoulder_width: tuple[float, float] = (0.0, 0.0)  # gravel shoulder outside the asphalt (no curb)
    verge_share: float = 0.0  # blocks with a grass strip between curb and sidewalk
    verge_width: tuple[float, float] = (1.0, 3.0)
    gutter_share: float = 0.0  # blocks with a concrete gutter pan on the road side of the curb
    gutter_width: tuple[float, float] = (0.4, 0.8)
    edge_line_share: float = 0.0  # streets with white edge lines near the asphalt's edge
    lane_paint_share: float = 1.0  # streets whose lane markings are painted at all
    road_materials: tuple[str, ...] = ("asphalt",)  # keys of materials.ROAD_MATERIALS, one drawn per city
    sidewalk_materials: tuple[str, ...] = ("concrete",)  # keys of materials.SIDEWALK_MATERIALS
    roof_palette: str = "grey"  # keys of materials.ROOF_PALETTES
    house_height: tuple[float, float] = (6.0, 16.0)
    house_width: tuple[float, float] = (5.0, 14.0)
    house_setback: tuple[float, float] = (0.0, 3.0)
    house_gap_share: float = 0.35  # houses followed by a gap (detached houses when high)
    house_gap: tuple[float, float] = (0.5, 4.0)
    building_share: float = 1.0  # places along a block where a building is attempted
    tower_share: float = 0.0  # buildings that are towers
    tower_height: tuple[float, float] = (40.0, 150.0)
    street_tree_share: float = 0.75  # blocks with street trees
    street_tree_setback: tuple[float, float] = (0.3, 0.6)  # crown centre from the curb, in sidewalk widths
    sun_reach: tuple[float, float] = (0.25, 0.6)  # shadow length per metre of height
    paved_yard_share: float = 0.0  # residential blocks whose yards are paved (plazas, courtyards)
    field_share: float = 0.0  # rural: blocks that are crop fields instead of lots and houses
    # residential yards: what real suburbs put beside the road that is *not* a road boundary
    bare_block_share: float = 0.0  # blocks without a sidewalk: the lawn meets the curb
    pitched_roof_share: float = 0.0  # houses with a gable or hip roof (sunlit and shaded facets, a ridge)
    house_driveway_share: float = 0.0  # houses with a paved driveway from the curb to the house (a car on 40 %)
    lot_fence_share: float = 0.0  # lot lines beside houses drawn as fences or hedges
    lawn_patch_share: float = 0.0  # lots whose lawn has its own shade (a patchwork of yards)
    pool_share: float = 0.0  # back yards with a swimming pool
    yard_canopy: tuple[float, float] = (0.0, 0.0)  # share of a residential yard under clumped tree crowns
    crown_lobes: int = 5  # lobes per crown; more draws the lumpy, sunlit/shaded crowns of real canopy
    # dense-urban photo look (style ``dense``): every knob off by default, drawing nothing
    road_wear_per_km: float = 0.0  # asphalt patches, tar seams, cracks and manholes per km of street
    car_detail: bool = False  # cars with windshields, rear windows, a lit roof, a short shadow; photo car colours
    flat_roof_detail: float = 0.0  # flat roofs with a parapet, rooftop units, water tanks, light wells
    relief_lean: tuple[float, float] = (0.0, 0.0)  # roofs shifted away from their footprints, m per m of height
    house_depth: tuple[float, float] = (10.0, 24.0)  # depth of a (non-lot) building from its front
    bare_tree_share: float = 0.0  # trees drawn leafless: a see-through crown of grey-brown branches
    bus_lane_share: float = (
        0.0  # avenues (18 m or wider) with a red bus lane or a green bike lane beside the parking lane
    )
    tree_pits: bool = False  # a soil square at the foot of every street tree
    court_share: float = 0.0  # parks that are sports fields or courts with painted white lines
    lot_stalls: bool = False  # parking lots are painted stalls with cars in them, not big buildings
    photo_texture: float = 0.0  # texture at every scale: stains, blotches, grain, gravel specks (DN)
    # camera look, drawn once per city from its own random stream
    source_gsd: tuple[float, float] | None = None  # sensor pixel size (m), resampled to ``gsd``
    haze: tuple[float, float] = (0.0, 0.0)  # blend towards a bright grey-blue veil
    saturation: tuple[float, float] = (1.0, 1.0)
    gamma: tuple[float, float] = (1.0, 1.0)
    colour_cast: float = 0.0  # +- per-band gain change of the whole city
    photo_blur: tuple[float, float] = (0.0, 0.0)  # Gaussian blur sigma (px) of the finished tile
    jpeg_quality: tuple[int, int] = (0, 0)  # JPEG round trip at a quality drawn in this range (0: none)


def city_rng(split: str, seed: int, *stream: int) -> np.random.Generator:
    """Random generator for (split, seed) and an optional sub-stream (e.g. a tile's row, col).

    The split is part of the entropy, so the three splits never share a city for any seed.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    return np.random.default_rng(np.random.SeedSequence([SPLITS.index(split), seed, *stream]))


def rng_share(rng: np.random.Generator, share: float) -> bool:
    """True with probability ``share``; draws nothing when ``share`` is 0, so a switched-off
    style knob leaves the random stream (and hence the city) unchanged."""
    return share > 0 and rng.random() < share
