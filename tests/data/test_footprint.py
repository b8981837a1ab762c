"""Tiles scattered over a city: windows, patches and review tiles come from where the imagery is
(data/footprint.py), not from the files' bounding box."""

from __future__ import annotations

import numpy as np
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.footprint import draw_window, footprint, groups, scaled, union_area
from csboundary.data.geotiff import write_geotiff
from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.data.model_view import model_view
from csboundary.data.raster import Mosaic
from csboundary.data.windows import PixelWindow
from csboundary.models.training.unlabelled import UnlabelledImagery
from csboundary.pipeline.training.adapt import imagery_groups, open_imagery_views
from csboundary.viz.review_page import pyramid_tiles, write_pyramid

W = PixelWindow
GAP_M = 5000.0  # metres between the scattered tiles


def scattered(folder, side: int = 200, gsd: float = 0.152, places=((0, 0), (1, 1), (0, 3))) -> list:
    """Tiles of ``side`` px, kilometres apart (``places`` in units of GAP_M), each one grey
    value, in one UTM CRS on one pixel grid."""
    folder.mkdir(parents=True, exist_ok=True)
    step = round(GAP_M / gsd) * gsd  # a whole number of pixels apart
    paths = []
    for k, (east, south) in enumerate(places):
        path = folder / f"t{k}.tif"
        write_geotiff(
            path,
            np.full((4, side, side), 60 + 20 * k, np.uint8),
            Affine(gsd, 0, 500000.0 + east * step, 0, -gsd, 4400000.0 - south * step),
            "EPSG:32618",
        )
        paths.append(path)
    return paths


def test_union_area_counts_overlaps_once():
    # 10x10 and 10x10 overlapping in a 5x5 square, and one apart: 100 + 100 - 25 + 4
    assert union_area([W(0, 0, 10, 10), W(5, 5, 10, 10), W(30, 30, 2, 2)]) == 179
    assert union_area([]) == 0 and union_area([W(3, 3, 0, 5)]) == 0


def test_tiles_together_are_their_box_and_groups_far_apart_are_their_own():
    box = W(0, 0, 5000, 3000)
    assert footprint([W(0, 0, 1000, 1000), W(1000, 0, 1000, 1000)], box) == [box]
    assert footprint([W(0, 0, 1000, 1000), W(1500, 1500, 1000, 1000)], box) == [
        box
    ]  # a missing tile: 500 px apart, one group
    assert footprint([W(-5, 0, 1000, 1000), W(100, 500, 1000, 1000), W(4000, 2000, 1000, 1000)], box) == [
        W(0, 0, 1100, 1500),
        W(4000, 2000, 1000, 1000),
    ]  # 2,900 px apart: two groups, each its box, clipped


def test_one_part_draws_what_two_integers_over_it_always_drew():
    part = W(0, 0, 900, 700)
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    for _ in range(20):
        col, row = int(b.integers(0, 900 - 256 + 1)), int(b.integers(0, 700 - 256 + 1))
        assert draw_window(a, [part], 256) == W(col, row, 256, 256)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 10**6), st.integers(0, 10**6), st.integers(1, 600), st.integers(1, 600)),
        min_size=1,
        max_size=6,
    ),
    st.integers(1, 300),
    st.integers(0, 2**32 - 1),
)
def test_every_drawn_window_lies_in_a_part_or_covers_it(boxes, size, seed):
    parts = [W(*b) for b in boxes]
    window = draw_window(np.random.default_rng(seed), parts, size)
    assert any(
        (p.contains(window) if p.width >= size and p.height >= size else window.intersection(p) is not None)
        for p in parts
    )


def test_parts_are_drawn_in_proportion_to_their_area():
    parts = [W(0, 0, 100, 100), W(10**6, 0, 300, 100)]  # 1 : 3
    rng = np.random.default_rng(0)
    second = sum(draw_window(rng, parts, 10).col_off >= 10**6 for _ in range(4000))
    assert abs(second / 4000 - 0.75) < 0.03


def test_scaled_parts_hold_the_source_pixels():
    # source pixels half the view's: [10, 31) -> view [5, 16); clipped to the view
    assert scaled([W(10, 4, 21, 6), W(190, 0, 30, 2)], 2.0, 2.0, W(0, 0, 100, 100)) == [W(5, 2, 11, 3), W(95, 0, 5, 1)]


def test_the_grid_plans_only_patches_whose_cores_meet_the_footprint():
    config = GridConfig(core=100, margin=10)
    grid = PatchGrid(1000, 600, config=config, footprint=[W(0, 0, 50, 50), W(850, 150, 200, 100)])
    assert [p.index for p in grid] == [(0, 0), (1, 8), (1, 9), (2, 8), (2, 9)] and len(grid) == 5
    assert sorted(q.index for q in grid.neighbours(grid.patch(1, 8))) == [(1, 9), (2, 8), (2, 9)]
    assert grid.neighbours(grid.patch(0, 0)) == []  # its unplanned neighbours hold no imagery: the mosaic's edge
    assert grid.patch(3, 3).core == W(300, 300, 100, 100)  # every patch of the rectangle is still there by index
    whole = PatchGrid(1000, 600, config=config, footprint=[W(0, 0, 1000, 600)])
    assert whole.planned is None and len(whole) == 60


def test_tiles_kilometres_apart_are_a_mosaic_of_their_windows(tmp_path):
    with Mosaic.open(scattered(tmp_path / "t")) as mosaic:
        assert mosaic.height > 90_000 and union_area(mosaic.footprint) == 3 * 200 * 200
        assert sorted(mosaic.footprint) == sorted(t.window for t in mosaic.tiles)
        grid = PatchGrid.for_mosaic(mosaic)
        assert 3 <= len(grid) <= 12 and all(mosaic.read(p.core).valid.any() for p in grid)  # a tile meets 1 to 4 cores
        view = model_view(mosaic, model_gsd=0.3).mosaic  # resampled to pixels twice as large
        assert union_area(view.footprint) == pytest.approx(3 * 100 * 100, rel=0.05)
        assert all(view.read(w).valid.mean() > 0.95 for w in view.footprint)


def test_adapt_draws_its_windows_where_the_scattered_tiles_are(tmp_path):
    """The case of issue 65: before, 50 windows drawn from the bounding box found no imagery."""
    groups = imagery_groups([tmp_path / "t" if scattered(tmp_path / "t") else None])
    views, mosaics = open_imagery_views(groups, None, 0.152)
    try:
        target = UnlabelledImagery(views, ["t"])
        assert target.pixels == 3 * 200 * 200
        rng = np.random.default_rng(0)
        shares = [target.sample(rng, 128)[1].mean() for _ in range(30)]
        assert min(shares) == 1.0
    finally:
        for mosaic in mosaics:
            mosaic.close()


def test_review_tiles_are_written_only_over_the_imagery(tmp_path):
    with Mosaic.open(scattered(tmp_path / "t", side=600)) as mosaic:
        made = pyramid_tiles(mosaic)
        assert len(made) == 3 * 4  # 600 px from a multiple of 512? each tile meets 2 x 2 tiles of 512 px at most
        levels = write_pyramid(mosaic, tmp_path / "tiles", progress=False)
        assert len(list((tmp_path / "tiles" / "0").glob("*.jpg"))) == len(made)
        assert len(list((tmp_path / "tiles" / str(levels - 1)).glob("*.jpg"))) == 1


def test_a_filled_mosaic_writes_the_same_pyramid_as_before(tmp_path):
    """Every tile written, each level the halved composite of the four below it."""
    write_geotiff(
        tmp_path / "a.tif",
        np.random.default_rng(0).integers(0, 255, (4, 700, 1100), np.uint8),
        Affine(0.152, 0, 500000.0, 0, -0.152, 4400000.0),
        "EPSG:32618",
    )
    with Mosaic.open(tmp_path / "a.tif") as mosaic:
        levels = write_pyramid(mosaic, tmp_path / "tiles", progress=False)
    import cv2

    assert levels == 3 and len(list((tmp_path / "tiles" / "0").glob("*.jpg"))) == 2 * 3
    assert cv2.imread(str(tmp_path / "tiles" / "1" / "0_0.jpg")).shape[:2] == (
        350,
        512,
    )  # rows (512 + 188) / 2, cols (512 + 512) / 2
    assert cv2.imread(str(tmp_path / "tiles" / "1" / "0_1.jpg")).shape[:2] == (350, 38)  # the last column: 76 / 2
    assert cv2.imread(str(tmp_path / "tiles" / "2" / "0_0.jpg")).shape[:2] == (175, 275)


def test_a_picture_without_crs_keeps_its_rows_going_down_when_resampled(tmp_path):
    """The case of issue 65: resampling a CRS-less picture flipped its y axis in world coordinates."""
    import rasterio

    with rasterio.open(tmp_path / "p.tif", "w", driver="GTiff", width=300, height=200, count=4, dtype="uint8") as dst:
        dst.write(np.full((4, 200, 300), 90, np.uint8))
    with Mosaic.open(tmp_path / "p.tif") as mosaic:
        view = model_view(mosaic, gsd=0.304).mosaic  # pixels of 0.304 m seen at 0.152: twice as many
        xs, ys = view.pixel_to_world(np.array([0.0, view.width]), np.array([0.0, view.height]))
        assert view.width == 600 and view.height == 400
        assert xs.tolist() == pytest.approx([0, 300]) and ys.tolist() == pytest.approx(
            [0, 200]
        )  # the picture's own pixels


def test_groups_join_tiles_less_than_the_gap_apart_and_part_the_others():
    side_by_side = [W(0, 0, 10, 10), W(10, 0, 10, 10), W(0, 10, 10, 10)]
    assert groups(side_by_side) == [W(0, 0, 20, 20)]
    assert groups([W(5000, 0, 10, 10), W(0, 0, 10, 10), W(10, 10, 5, 5)]) == [W(0, 0, 15, 15), W(5000, 0, 10, 10)]
    chain = [
        W(0, 0, 10, 10),
        W(1030, 0, 10, 10),
        W(2060, 0, 10, 10),
    ]  # each 1,020 px from the next: one group through the middle
    assert groups(chain) == [W(0, 0, 2070, 10)] and len(groups(chain, gap=1000)) == 3


def test_a_labelled_city_of_scattered_tiles_trains_as_one_city_per_group(tmp_path):
    """No raster of the city spans the kilometres between its tiles; each part samples its own imagery and labels."""
    import geopandas as gpd
    from shapely.geometry import LineString

    from csboundary.data.user_city import make_city
    from csboundary.models.training.data import TrainingCity

    tiles = scattered(tmp_path / "t", side=300)
    with Mosaic.open(tiles) as mosaic:
        ends = [
            mosaic.pixel_to_world(np.array([w.col_off + 20.0, w.col_end - 20.0]), np.full(2, w.row_off + 150.0))
            for w in mosaic.footprint
        ]  # a line across the middle of each tile
    lines = [LineString(list(zip(xs, ys))) for xs, ys in ends]
    gpd.GeoDataFrame(geometry=lines, crs="EPSG:32618").to_file(tmp_path / "gt.gpkg")
    make_city(tiles, tmp_path / "gt.gpkg", tmp_path / "city")
    parts = TrainingCity.parts(tmp_path / "city")
    try:
        assert [(p.mosaic.width, p.mosaic.height) for p in parts] == [(300, 300)] * 3
        rng = np.random.default_rng(0)
        for part in parts:
            image, targets, valid = part.fpn_sample(part.random_window(rng, 128))
            assert valid.all()
            full = part.fpn_sample(PixelWindow(0, 0, 300, 300))[1][
                1
            ]  # the segmentation of the whole part: its one line
            assert full[150, 150] > 0 and full[20, 150] == 0
    finally:
        for part in parts:
            part.close()


def test_a_16_bit_stretch_and_the_evaluation_grid_follow_the_groups(tmp_path):
    """A stretch from an overview of each group (the box's overview shrinks each tile to a few
    pixels), and evaluate's patch grid planned over the raster's groups, not its box."""
    from csboundary.data.model_view import fit_stretch
    from csboundary.graph import BoundaryGraph
    from csboundary.metrics.io import frame_from_raster, grid_for

    folder = tmp_path / "t"
    folder.mkdir()
    for k, (east, value) in enumerate([(0, 1000), (60_000, 3000)]):
        write_geotiff(
            folder / f"t{k}.tif",
            np.full((4, 200, 200), value, np.uint16),
            Affine(0.152, 0, 500000.0 + east * 0.152, 0, -0.152, 4400000.0),
            "EPSG:32618",
        )
    with Mosaic.open(folder) as mosaic:
        stretch = fit_stretch(mosaic)
    assert stretch.low == pytest.approx((1000,) * 4) and stretch.high == pytest.approx((3000,) * 4)
    frame = frame_from_raster(folder)
    assert len(frame.footprint) == 2
    empty = BoundaryGraph(np.zeros((0, 2)), np.zeros((0, 2), np.int64))
    assert len(grid_for(frame, empty, empty)) == 2  # of a 1 x 61 grid
