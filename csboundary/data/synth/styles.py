"""Named, seeded styles of synthetic city: the family of worlds the detector is trained on.

A style is a set of :class:`SynthConfig` overrides; a city is reproduced from (style, split,
seed). ``classic`` is the original generator (a NYC-like grid, one look), kept byte for byte so
the cities and scores recorded before styles existed stay valid. The others vary street layout
*and* appearance; each draws its camera look (sensor pixel size 0.10-0.30 m resampled to the
model's 0.152 m, haze, saturation, gamma, colour cast) per city.

``MAJOR_STYLES`` are the ones a leave-one-style-out evaluation holds out in turn.
"""

from __future__ import annotations

import numpy as np

from csboundary.data.synth.config import SynthConfig, city_rng

# The camera look shared by every style but classic: any sensor, any afternoon.
_VARIED_LOOK = {
    "source_gsd": (0.10, 0.30),
    "haze": (0.0, 0.25),
    "saturation": (0.65, 1.25),
    "gamma": (0.8, 1.25),
    "colour_cast": 0.08,
    "noise_sigma": 4.0,
}
_ANY_MATERIAL = {
    "road_materials": ("asphalt", "asphalt_new", "asphalt_old", "asphalt_warm", "concrete_road"),
    "sidewalk_materials": ("concrete", "concrete_dark", "pavers_red", "pavers_grey", "asphalt_walk"),
    "roof_palette": "mixed",
}

# North-American residential streets: a loosely curving grid of detached houses on lawns,
# most blocks without a sidewalk (lawn to the curb), pitched roofs, a paved driveway from the
# curb to nearly every house (often with a car on it), fences and hedges on the lot lines,
# a patchwork of lawn shades, pools: the yard edges that are not road boundaries.
_RESIDENTIAL = {
    "bearing_deg": (-90.0, 90.0),
    "avenue_spacing": (150.0, 300.0),
    "street_spacing": (70.0, 130.0),
    "avenue_width": (9.0, 14.0),
    "street_width": (7.5, 11.0),
    "cross_street_skew_deg": 15.0,
    "curved_street_share": 0.35,
    "avenue_curve_share": 0.2,
    "curve_amplitude": (10.0, 40.0),
    "boulevard_share": 0.05,
    "diagonals_per_km2": 0.3,
    "dropped_segment_share": 0.1,
    "dead_end_share": 0.08,
    "cul_de_sac_share": 0.7,
    "island_share": 0.05,
    "curb_radius": (5.0, 12.0),
    "sharp_block_share": 0.03,
    "sidewalk_width": (1.5, 2.2),
    "bare_block_share": 0.6,
    "verge_share": 0.3,
    "verge_width": (1.5, 4.0),
    "park_share": 0.06,
    "lot_share": 0.05,
    "house_width": (9.0, 18.0),
    "house_height": (5.0, 9.0),
    "house_setback": (6.0, 12.0),
    "house_gap_share": 1.0,
    "house_gap": (3.0, 10.0),
    "driveway_spacing": (40.0, 90.0),
    "street_tree_share": 0.5,
    "street_tree_radius": (2.5, 6.0),
    "street_tree_setback": (0.5, 2.0),
    "parked_car_occupancy": (0.0, 0.15),
    "moving_cars_per_km": 6.0,
    "lane_paint_share": 0.2,
    "crosswalk_share": 0.1,
    "pitched_roof_share": 0.85,
    "house_driveway_share": 0.8,
    "lot_fence_share": 0.5,
    "lawn_patch_share": 0.7,
    "pool_share": 0.1,
    **_ANY_MATERIAL,
    **_VARIED_LOOK,
}

STYLES: dict[str, dict] = {
    # The original generator: NYC-like avenues and cross streets within 35 degrees of north.
    "classic": {},
    # A grid at any bearing with every material, gutters, verges and roundabouts; the same
    # street geometry family as classic, in any look.
    "grid": {
        "bearing_deg": (-90.0, 90.0),
        "verge_share": 0.3,
        "gutter_share": 0.35,
        "roundabout_share": 0.03,
        "parked_car_occupancy": (0.0, 1.0),
        "street_tree_share": 0.6,
        **_ANY_MATERIAL,
        **_VARIED_LOOK,
    },
    # Dense downtown: rotated grid, diagonal avenues cutting blocks into triangles, boulevards
    # with medians, traffic islands and plazas, towers throwing long shadows across the street,
    # parked cars up to bumper-to-bumper.
    "downtown": {
        "bearing_deg": (-90.0, 90.0),
        "avenue_spacing": (110.0, 200.0),
        "street_spacing": (55.0, 95.0),
        "avenue_width": (14.0, 22.0),
        "street_width": (9.0, 14.0),
        "cross_street_skew_deg": 12.0,
        "boulevard_share": 0.45,
        "median_width": (2.0, 8.0),
        "diagonals_per_km2": 3.0,
        "curved_street_share": 0.05,
        "dropped_segment_share": 0.05,
        "dead_end_share": 0.03,
        "island_share": 0.45,
        "curb_radius": (2.0, 8.0),
        "sharp_block_share": 0.25,
        "sidewalk_width": (3.0, 7.0),
        "park_share": 0.06,
        "lot_share": 0.08,
        "parked_car_occupancy": (0.6, 1.0),
        "parked_car_spacing": 5.6,
        "moving_cars_per_km": 60.0,
        "house_width": (12.0, 30.0),
        "house_height": (12.0, 45.0),
        "house_setback": (0.0, 1.0),
        "house_gap_share": 0.1,
        "tower_share": 0.45,
        "paved_yard_share": 0.8,
        "tower_height": (40.0, 160.0),
        "sun_reach": (0.4, 1.1),
        "street_tree_share": 0.45,
        "crosswalk_share": 0.9,
        "gutter_share": 0.4,
        **_ANY_MATERIAL,
        "roof_palette": "dark",
        **_VARIED_LOOK,
    },
    # Curvy suburbs: curving collectors, local streets leaving them at T-junctions and ending in
    # cul-de-sacs (some with a planted centre island) or looping back as crescents; roundabouts;
    # detached houses set back behind lawns, driveways across the curb, canopy over the curb,
    # grass verges, few parked cars.
    "suburb": {
        "layout": "suburb",
        "bearing_deg": (-90.0, 90.0),
        "avenue_spacing": (200.0, 380.0),
        "street_spacing": (200.0, 380.0),
        "branch_spacing": (45.0, 90.0),
        "avenue_width": (10.0, 14.0),
        "street_width": (7.0, 10.0),
        "cross_street_skew_deg": 20.0,
        "curved_street_share": 1.0,
        "avenue_curve_share": 1.0,
        "curve_amplitude": (20.0, 60.0),
        "boulevard_share": 0.1,
        "diagonals_per_km2": 0.0,
        "dropped_segment_share": 0.1,
        "dead_end_share": 0.05,
        "cul_de_sac_share": 0.8,
        "bulb_island_share": 0.35,
        "roundabout_share": 0.3,
        "island_share": 0.1,
        "curb_radius": (6.0, 14.0),
        "sharp_block_share": 0.02,
        "sidewalk_width": (1.5, 2.5),
        "verge_share": 0.6,
        "verge_width": (1.5, 4.0),
        "park_share": 0.12,
        "lot_share": 0.05,
        "house_width": (9.0, 16.0),
        "house_height": (5.0, 9.0),
        "house_setback": (5.0, 10.0),
        "house_gap_share": 1.0,
        "house_gap": (4.0, 12.0),
        "driveway_spacing": (12.0, 25.0),
        "street_tree_share": 0.8,
        "street_tree_radius": (3.0, 6.5),
        "parked_car_occupancy": (0.0, 0.2),
        "moving_cars_per_km": 8.0,
        "lane_paint_share": 0.3,
        "crosswalk_share": 0.15,
        **_ANY_MATERIAL,
        "roof_palette": "mixed",
        **_VARIED_LOOK,
    },
    # Rural roads: narrow curving asphalt with no raised curb (asphalt onto a gravel or soil
    # shoulder and grass), edge lines, crop fields, sparse farmhouses set far back.
    "rural": {
        "bearing_deg": (-90.0, 90.0),
        "avenue_spacing": (150.0, 320.0),
        "street_spacing": (130.0, 300.0),
        "avenue_width": (6.5, 9.5),
        "street_width": (5.5, 7.5),
        "cross_street_skew_deg": 25.0,
        "curved_street_share": 0.6,
        "avenue_curve_share": 0.5,
        "curve_amplitude": (20.0, 60.0),
        "boulevard_share": 0.0,
        "diagonals_per_km2": 0.5,
        "dropped_segment_share": 0.35,
        "dead_end_share": 0.1,
        "cul_de_sac_share": 0.2,
        "island_share": 0.0,
        "roundabout_share": 0.08,
        "curb_radius": (8.0, 20.0),
        "sharp_block_share": 0.05,
        "raised_curb": False,
        "sidewalk_width": (0.0, 0.0),
        "shoulder_width": (0.3, 1.8),
        "park_share": 0.1,
        "lot_share": 0.03,
        "field_share": 0.6,
        "building_share": 0.35,
        "house_width": (10.0, 20.0),
        "house_height": (5.0, 10.0),
        "house_setback": (10.0, 30.0),
        "house_gap_share": 1.0,
        "house_gap": (10.0, 40.0),
        "driveway_spacing": (40.0, 120.0),
        "street_tree_share": 0.35,
        "street_tree_setback": (1.0, 2.5),
        "parked_car_occupancy": (0.0, 0.03),
        "moving_cars_per_km": 4.0,
        "edge_line_share": 0.6,
        "lane_paint_share": 0.6,
        "crosswalk_share": 0.0,
        "road_materials": ("asphalt", "asphalt_new", "asphalt_old", "asphalt_warm"),
        "roof_palette": "mixed",
        **_VARIED_LOOK,
    },
    "residential": _RESIDENTIAL,
    # Leafy suburb: the residential streets under a mature canopy. Clumps of big crowns cover a
    # quarter to half of every yard and overhang the curb, lit on the sun's side and dark in
    # between; their outline against the lawn is as sharp as a road edge and is not one.
    "leafy": {
        **_RESIDENTIAL,
        "street_tree_share": 0.8,
        "street_tree_radius": (3.5, 7.5),
        "street_tree_setback": (0.3, 2.5),
        "yard_canopy": (0.2, 0.5),
        "crown_lobes": 12,
    },
    # Motorway through a sparse grid: one or two highways with medians that only the avenues
    # cross, each crossing a diamond interchange (four ramps curving off the outer lane, grassy
    # gores between ramp and highway); side streets stop short of the highway; commercial lots,
    # no sidewalks on a third of the blocks, dense traffic on the highway.
    "highway": {
        "bearing_deg": (-90.0, 90.0),
        "highways": 1,
        "avenue_spacing": (220.0, 400.0),
        "street_spacing": (90.0, 180.0),
        "avenue_width": (11.0, 16.0),
        "street_width": (8.0, 11.0),
        "cross_street_skew_deg": 15.0,
        "curved_street_share": 0.3,
        "boulevard_share": 0.15,
        "diagonals_per_km2": 0.2,
        "dropped_segment_share": 0.2,
        "dead_end_share": 0.05,
        "island_share": 0.05,
        "curb_radius": (6.0, 15.0),
        "sharp_block_share": 0.05,
        "sidewalk_width": (1.5, 3.0),
        "bare_block_share": 0.35,
        "verge_share": 0.4,
        "verge_width": (2.0, 6.0),
        "park_share": 0.2,
        "lot_share": 0.25,
        "house_width": (12.0, 35.0),
        "house_height": (5.0, 15.0),
        "house_setback": (5.0, 20.0),
        "house_gap_share": 1.0,
        "house_gap": (8.0, 30.0),
        "street_tree_share": 0.3,
        "parked_car_occupancy": (0.0, 0.2),
        "moving_cars_per_km": 40.0,
        "edge_line_share": 0.3,
        "crosswalk_share": 0.3,
        "gutter_share": 0.2,
        **_ANY_MATERIAL,
        **_VARIED_LOOK,
    },
    # Dense city (New York at 0.152 m): a grid of 10-18 m streets and 18-30 m avenues around
    # 60 x 150-250 m blocks, sharp-ish curb returns, wide sidewalks with tree pits, attached
    # flat-roofed buildings filling every block front (parapets, rooftop units, water tanks,
    # light wells; roofs leaning off their footprints), both curbs lined with parked cars,
    # dense traffic, crosswalks, schoolyards and sports fields, striped parking lots, towers'
    # shadows across the street, worn and patched asphalt, blur and JPEG compression.
    "dense": {
        "bearing_deg": (-90.0, 90.0),
        "avenue_spacing": (175.0, 275.0),
        "street_spacing": (72.0, 78.0),
        "avenue_width": (18.0, 30.0),
        "street_width": (10.0, 18.0),
        "cross_street_skew_deg": 3.0,
        "boulevard_share": 0.08,
        "median_width": (2.0, 5.0),
        "diagonals_per_km2": 0.3,
        "curved_street_share": 0.0,
        "dropped_segment_share": 0.03,
        "dead_end_share": 0.02,
        "cul_de_sac_share": 0.0,
        "island_share": 0.1,
        "curb_radius": (3.0, 8.0),
        "sharp_block_share": 0.05,
        "sidewalk_width": (3.0, 6.0),
        "park_share": 0.05,
        "lot_share": 0.05,
        "court_share": 0.7,
        "lot_stalls": True,
        "street_tree_share": 0.75,
        "street_tree_spacing": (6.0, 12.0),
        "street_tree_radius": (2.0, 4.5),
        "street_tree_setback": (0.2, 0.3),
        "tree_pits": True,
        "bus_lane_share": 0.35,
        "bare_tree_share": 0.6,
        "parked_car_occupancy": (0.8, 1.0),
        "parked_car_spacing": 5.8,
        "moving_cars_per_km": 70.0,
        "crosswalk_share": 0.85,
        "driveway_spacing": (250.0, 600.0),
        "house_width": (5.0, 16.0),
        "house_depth": (14.0, 23.0),
        "house_height": (10.0, 30.0),
        "house_setback": (1.0, 1.4),  # nearly flush with the sidewalk (stoops, areaways)
        "house_gap_share": 0.0,
        "tower_share": 0.12,
        "tower_height": (40.0, 150.0),
        "sun_reach": (0.2, 0.6),
        "paved_yard_share": 0.7,
        "road_materials": ("asphalt_old", "concrete_road", "asphalt"),
        "roof_palette": "tar",
        "road_wear_per_km": 400.0,
        "car_detail": True,
        "flat_roof_detail": 0.85,
        "relief_lean": (0.02, 0.06),
        "photo_texture": 2.5,
        **_VARIED_LOOK,
        "source_gsd": (0.12, 0.2),
        "haze": (0.0, 0.12),
        "saturation": (0.75, 1.05),
        "colour_cast": 0.05,
        "gamma": (0.85, 1.1),
        "photo_blur": (0.4, 0.9),
        "jpeg_quality": (60, 85),
    },
    # Old town: an irregular grid of narrow streets, strongly skewed and bent, sharp corners,
    # small plazas (traffic islands), row houses with warm roofs.
    "irregular": {
        "bearing_deg": (-90.0, 90.0),
        "avenue_spacing": (70.0, 150.0),
        "street_spacing": (40.0, 90.0),
        "avenue_width": (9.0, 14.0),
        "street_width": (6.0, 10.0),
        "cross_street_skew_deg": 25.0,
        "curved_street_share": 0.4,
        "avenue_curve_share": 0.3,
        "curve_amplitude": (5.0, 20.0),
        "diagonals_per_km2": 2.0,
        "dropped_segment_share": 0.15,
        "dead_end_share": 0.1,
        "boulevard_share": 0.05,
        "island_share": 0.3,
        "curb_radius": (1.0, 5.0),
        "sharp_block_share": 0.4,
        "sidewalk_width": (1.5, 3.0),
        "parked_car_occupancy": (0.2, 0.8),
        "house_gap_share": 0.1,
        "street_tree_share": 0.3,
        **_ANY_MATERIAL,
        "roof_palette": "warm",
        "paved_yard_share": 0.3,
        **_VARIED_LOOK,
    },
}

MAJOR_STYLES = ("grid", "downtown", "suburb", "rural")
MIX = "mix"  # a style drawn per city from ``DEFAULT_MIX``
DEFAULT_MIX = {"classic": 1.0, "grid": 1.0, "downtown": 1.0, "suburb": 1.0, "rural": 1.0, "irregular": 1.0}


def style_config(style: str, **overrides) -> SynthConfig:
    """The :class:`SynthConfig` of a named style, with ``overrides`` (e.g. tile_size) on top."""
    if style not in STYLES:
        raise ValueError(f"unknown style {style!r}; choose one of {', '.join(STYLES)} or {MIX}")
    return SynthConfig(**{**STYLES[style], **overrides, "style": style})


def draw_style(split: str, seed: int, weights: dict[str, float] | None = None) -> str:
    """The style of city (split, seed) in a random mix: seeded, so a mixed city is reproducible."""
    weights = DEFAULT_MIX if weights is None else weights
    names = [n for n, w in weights.items() if w > 0]
    unknown = [n for n in names if n not in STYLES]
    if not names or unknown:
        raise ValueError(f"a style mix needs positive weights on known styles; got {weights}")
    p = np.array([weights[n] for n in names], float)
    return names[int(city_rng(split, seed, 3).choice(len(names), p=p / p.sum()))]
