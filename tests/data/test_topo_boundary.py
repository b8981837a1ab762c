"""Topo-boundary import, on tiny files fabricated in exactly the dataset's format (20 px patches)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning

from csboundary.data.city_layout import ground_truth_path, read_meta, tiles_dir
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.data.topo_boundary import (
    Piece,
    assemble_tile,
    import_topo_boundary,
    join_pieces,
    parse_patch_id,
    patch_id,
    pixels_to_line,
    scan,
)
from csboundary.errors import InputError, InputWarning

PS = 20  # patch size of the fabricated dataset
TILE = "000123"
X0, Y0 = 980_000.0, 200_000.0  # a tile origin in EPSG:2263 (feet) for the georeferenced case


def patch_pixels(row: int, col: int, bands: int = 4) -> np.ndarray:
    """Distinct, position-dependent pixels so misplacement is detectable."""
    rng = np.random.default_rng(100 * row + col)
    return rng.integers(1, 256, size=(bands, PS, PS), dtype=np.uint8)


def write_patch(path: Path, pixels: np.ndarray, crs=None, transform=None) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    profile = dict(driver="GTiff", width=pixels.shape[2], height=pixels.shape[1], count=pixels.shape[0], dtype="uint8")
    if crs is not None:
        profile.update(crs=crs, transform=transform)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", **profile) as dst:
            dst.write(pixels)
    return path


def write_labels(root: Path, pid: str, seqs: list[list[list[int]]]) -> Path:
    path = root / "dataset" / "labels" / "dense_seq" / f"{pid}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    items = [{"init_vertex": s[0], "end_vertex": s[-1], "seq": s} for s in seqs]
    path.write_text(json.dumps(items))
    return path


def make_dataset(root: Path, splits: int = 2, skip=(), georef: bool = False, labels=None, tile: str = TILE) -> Path:
    """The benchmark's layout: dataset/cropped_tiff, dataset/labels/dense_seq, dataset/data_split.json."""
    split = {"train": [], "valid": [], "test": [], "pretrain": []}
    names = list(split)
    for r in range(splits):
        for c in range(splits):
            pid = patch_id(tile, r, c)
            split[names[(r * splits + c) % 4]].append(pid)
            if (r, c) in skip:
                continue
            kwargs = {}
            if georef:
                kwargs = dict(crs="EPSG:2263", transform=Affine(0.5, 0, X0 + c * PS * 0.5, 0, -0.5, Y0 - r * PS * 0.5))
            write_patch(root / "dataset" / "cropped_tiff" / f"{pid}.tiff", patch_pixels(r, c), **kwargs)
            write_labels(root, pid, (labels or {}).get((r, c), []))
    (root / "dataset" / SPLIT_NAME).write_text(json.dumps(split))
    return root


SPLIT_NAME = "data_split.json"

# A boundary along row 5 that crosses from patch (0, 0) into (0, 1) and drops one row at the
# border (a diagonal step, 1.41 px), the second piece stored in the opposite direction.
CROSSING = {
    (0, 0): [[[5, 15], [5, 16], [5, 17], [5, 18], [5, 19]], [[12, 2], [12, 3], [12, 4]]],
    (0, 1): [[[6, 2], [6, 1], [6, 0]]],
}


def assemble_quiet(index, tile=TILE, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InputWarning)
        return assemble_tile(index, tile, **kw)


def import_quiet(root, out, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InputWarning)
        return import_topo_boundary(root, out, patch_size=PS, progress=False, **kw)


# -- names and scanning -----------------------------------------------------------------------------
def test_patch_ids_parse():
    assert patch_id("000123", 2, 1) == "000123_21"
    assert parse_patch_id("000123_21") == ("000123", 2, 1)
    assert parse_patch_id("00123_21") is None and parse_patch_id("000123_2") is None


def test_scan_finds_patches_labels_and_split(tmp_path):
    make_dataset(tmp_path, labels=CROSSING)
    (tmp_path / "dataset" / "cropped_tiff" / "notes.tiff").write_text("not a patch name")  # ignored
    index = scan(tmp_path)
    assert index.tile_ids == [TILE]
    assert sorted(index.patches[TILE]) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert set(index.labels) == {f"{TILE}_00", f"{TILE}_01", f"{TILE}_10", f"{TILE}_11"}
    assert index.split == {f"{TILE}_00": "train", f"{TILE}_01": "valid", f"{TILE}_10": "test", f"{TILE}_11": "pretrain"}
    assert index.split_file == tmp_path / "dataset" / "data_split.json"


def test_split_file_listing_a_patch_twice_is_an_input_error(tmp_path):
    make_dataset(tmp_path)
    bad = tmp_path / "dataset" / "data_split.json"
    bad.write_text(json.dumps({"train": [f"{TILE}_00"], "test": [f"{TILE}_00"]}))
    with pytest.raises(InputError, match="both train and test") as err:
        scan(tmp_path)
    assert str(bad) in str(err.value)


# -- reassembly -------------------------------------------------------------------------------------
def test_patches_reassemble_in_the_right_place(tmp_path):
    make_dataset(tmp_path, splits=5)
    tile = assemble_quiet(scan(tmp_path), patch_size=PS, splits=5)
    assert tile.image.shape == (4, 5 * PS, 5 * PS) and tile.image.dtype == np.uint8
    assert tile.valid.all() and tile.missing == []
    for R, C, r, c in [(0, 0, 0, 0), (2, 1, 3, 17), (4, 4, 19, 19), (1, 3, 10, 0), (3, 0, 0, 19)]:
        np.testing.assert_array_equal(tile.image[:, R * PS + r, C * PS + c], patch_pixels(R, C)[:, r, c])
    for R in range(5):
        for C in range(5):
            np.testing.assert_array_equal(
                tile.image[:, R * PS : (R + 1) * PS, C * PS : (C + 1) * PS], patch_pixels(R, C)
            )


def test_boundary_crossing_a_patch_border_becomes_one_linestring(tmp_path):
    make_dataset(tmp_path, labels=CROSSING)
    tile = assemble_quiet(scan(tmp_path), patch_size=PS, splits=2)
    assert len(tile.lines) == 2
    crossing = [ln for ln, src in zip(tile.lines, tile.line_sources) if len(src) == 2]
    assert len(crossing) == 1
    # tile pixels [row, col]: (5,15)..(5,19) then (6,20),(6,21),(6,22); centre = (col+0.5, row+0.5) px,
    # not georeferenced -> x = 0.5 * (col + 0.5), y = -0.5 * (row + 0.5)
    # The staircase is simplified (0.75 px): every pixel centre lies within 0.57 px of the chord
    # from the first to the last, so only the ends remain.
    np.testing.assert_allclose(np.asarray(crossing[0].coords), [(7.75, -2.75), (11.25, -3.25)])
    every_pixel = [
        (7.75, -2.75),
        (8.25, -2.75),
        (8.75, -2.75),
        (9.25, -2.75),
        (9.75, -2.75),
        (10.25, -3.25),
        (10.75, -3.25),
        (11.25, -3.25),
    ]
    chain = np.array([[5, 15], [5, 16], [5, 17], [5, 18], [5, 19], [6, 20], [6, 21], [6, 22]])
    np.testing.assert_allclose(np.asarray(pixels_to_line(tile.transform, chain, simplify_px=0).coords), every_pixel)
    other = [ln for ln, src in zip(tile.lines, tile.line_sources) if len(src) == 1][0]
    np.testing.assert_allclose(
        np.asarray(other.coords), [(1.25, -6.25), (2.25, -6.25)]
    )  # collinear middle point simplified away


def test_join_pieces_rings_corners_and_forks():
    pts = lambda *p: np.array(p, dtype=float)  # noqa: E731
    # A ring cut into two halves by a vertical border between col 19 and col 20.
    ring = join_pieces(
        [
            Piece("a", pts([0, 19], [0, 18], [1, 18], [1, 19])),
            Piece("b", pts([1, 20], [1, 21], [0, 21], [0, 20])),
        ]
    )
    assert len(ring) == 1 and ring[0][1] == ["a", "b"]
    assert (ring[0][0][0] == ring[0][0][-1]).all() and len(ring[0][0]) == 9
    # Ends closer than 1.5 px in the same patch are not joined (they are separate boundaries).
    assert len(join_pieces([Piece("a", pts([0, 0], [0, 5])), Piece("a", pts([0, 6], [0, 9]))])) == 2
    # A one-pixel piece clipped by a patch corner still links its neighbours.
    corner = join_pieces(
        [
            Piece("00", pts([17, 17], [19, 19])),
            Piece("01", pts([20, 20])),
            Piece("11", pts([21, 21], [25, 25])),
        ]
    )
    assert len(corner) == 1 and corner[0][1] == ["00", "01", "11"]
    # Three ends meeting: the closest pair joins, the third stays an end (no forks).
    fork = join_pieces(
        [
            Piece("a", pts([0, 10], [5, 19])),
            Piece("b", pts([5, 20], [5, 30])),
            Piece("c", pts([6, 20], [9, 30])),
        ]
    )
    assert sorted(src for _, src in fork) == [["a", "b"], ["c"]]
    assert join_pieces([Piece("a", pts([3, 3]))]) == []  # fewer than 2 points: skipped


def test_missing_patch_is_masked_reported_and_imported(tmp_path):
    make_dataset(tmp_path, skip={(1, 1)}, labels=CROSSING)
    tile = assemble_quiet(scan(tmp_path), patch_size=PS, splits=2)
    assert tile.missing == [f"{TILE}_11"]
    assert not tile.valid[PS:, PS:].any() and tile.valid[:PS, :].all() and tile.valid[:, :PS].all()
    assert (tile.image[:, PS:, PS:] == 0).all()

    report = import_quiet(tmp_path, tmp_path / "out", splits=2)
    assert report["tiles_written"] == [TILE]
    assert report["missing_patches"] == [f"{TILE}_11"]
    city = tmp_path / "out" / TILE
    assert read_meta(city)["missing_patches"] == [f"{TILE}_11"]
    with Mosaic.open(tiles_dir(city)) as mosaic:
        got = mosaic.read(mosaic.window)
    np.testing.assert_array_equal(got.valid, tile.valid)


def test_missing_label_file_means_no_boundaries_and_is_reported(tmp_path):
    make_dataset(tmp_path, labels=CROSSING)
    (tmp_path / "dataset" / "labels" / "dense_seq" / f"{TILE}_01.json").unlink()
    report = import_quiet(tmp_path, tmp_path / "out", splits=2)
    assert report["unlabelled_patches"] == [f"{TILE}_01"]
    assert report["tiles"][TILE]["boundaries"] == 2  # the (0, 0) pieces, now unjoined
    assert read_meta(tmp_path / "out" / TILE)["unlabelled_patches"] == [f"{TILE}_01"]


# -- georeference -----------------------------------------------------------------------------------
def test_georeferenced_patches_give_the_tile_transform(tmp_path):
    make_dataset(tmp_path, georef=True, labels=CROSSING)
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)  # georeferenced: no fallback warning
        tile = assemble_tile(scan(tmp_path), TILE, patch_size=PS, splits=2)
    assert tile.georeferenced and tile.crs == "EPSG:2263"
    assert tile.transform.almost_equals(Affine(0.5, 0, X0, 0, -0.5, Y0))
    crossing = [ln for ln, src in zip(tile.lines, tile.line_sources) if len(src) == 2][0]
    # first point: tile pixel (row 5, col 15) -> centre (15.5, 5.5) px -> (X0 + 7.75, Y0 - 2.75)
    np.testing.assert_allclose(crossing.coords[0], (X0 + 7.75, Y0 - 2.75))
    np.testing.assert_allclose(crossing.coords[-1], (X0 + 11.25, Y0 - 3.25))


def test_georeferenced_patches_that_disagree_are_an_input_error(tmp_path):
    make_dataset(tmp_path, georef=True)
    moved = tmp_path / "dataset" / "cropped_tiff" / f"{TILE}_11.tiff"
    write_patch(moved, patch_pixels(1, 1), crs="EPSG:2263", transform=Affine(0.5, 0, X0 + 50, 0, -0.5, Y0 - 10))
    with pytest.raises(InputError) as err:
        assemble_tile(scan(tmp_path), TILE, patch_size=PS, splits=2)
    assert str(moved) in str(err.value) and "\n" not in str(err.value)


def test_not_georeferenced_falls_back_to_epsg2263_half_foot_pixels(tmp_path):
    make_dataset(tmp_path, labels=CROSSING)
    with pytest.warns(InputWarning, match="not georeferenced"):
        report = import_topo_boundary(tmp_path, tmp_path / "out", patch_size=PS, splits=2, progress=False)
    assert report["not_georeferenced"] == [TILE]
    city = tmp_path / "out" / TILE
    meta = read_meta(city)
    assert meta["source"] == "topo-boundary" and meta["tile_id"] == TILE
    assert meta["crs"] == "EPSG:2263" and meta["gsd"] == 0.5 and meta["georeferenced"] is False
    assert meta["patch_split"] == {
        f"{TILE}_00": "train",
        f"{TILE}_01": "valid",
        f"{TILE}_10": "test",
        f"{TILE}_11": "pretrain",
    }
    with rasterio.open(tiles_dir(city) / f"{TILE}.tif") as ds:
        assert ds.crs.to_epsg() == 2263
        assert ds.transform == Affine(0.5, 0, 0, 0, -0.5, 0)
        assert ds.tags()["tile_id"] == TILE


# -- bad input --------------------------------------------------------------------------------------
def test_non_raster_tiff_is_an_input_error_naming_it(tmp_path):
    make_dataset(tmp_path)
    bad = tmp_path / "dataset" / "cropped_tiff" / f"{TILE}_10.tiff"
    bad.write_text("this is not an image\n")
    with pytest.raises(InputError) as err:
        import_quiet(tmp_path, tmp_path / "out", splits=2)
    assert err.value.path == str(bad) and str(bad) in str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    "pixels, problem",
    [(np.zeros((4, PS, PS + 1), np.uint8), "21x20"), (np.zeros((2, PS, PS), np.uint8), "2 band")],
)
def test_wrong_size_or_too_few_bands_is_an_input_error(tmp_path, pixels, problem):
    make_dataset(tmp_path)
    bad = write_patch(tmp_path / "dataset" / "cropped_tiff" / f"{TILE}_01.tiff", pixels)
    with pytest.raises(InputError, match=problem) as err:
        assemble_quiet(scan(tmp_path), patch_size=PS, splits=2)
    assert err.value.path == str(bad)


def test_malformed_label_file_is_an_input_error_naming_it(tmp_path):
    make_dataset(tmp_path)
    bad = write_labels(tmp_path, f"{TILE}_00", [])
    bad.write_text(json.dumps([{"init_vertex": [0, 0], "seq": [[1, 2, 3]]}]))
    with pytest.raises(InputError, match="boundary 0") as err:
        assemble_quiet(scan(tmp_path), patch_size=PS, splits=2)
    assert err.value.path == str(bad)


def test_folder_without_patches_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no Topo-boundary patches"):
        import_topo_boundary(tmp_path, tmp_path / "out", progress=False)


# -- output -----------------------------------------------------------------------------------------
def test_import_output_opens_as_mosaic_and_ground_truth(tmp_path):
    make_dataset(tmp_path, georef=True, labels=CROSSING)
    report = import_topo_boundary(tmp_path, tmp_path / "out", patch_size=PS, splits=2, progress=False)
    city = Path(report["tiles"][TILE]["city_dir"])
    tile = assemble_tile(scan(tmp_path), TILE, patch_size=PS, splits=2)
    with Mosaic.open(tiles_dir(city)) as mosaic:
        assert mosaic.crs.to_epsg() == 2263
        assert mosaic.transform.almost_equals(tile.transform)
        got = mosaic.read(mosaic.window)
    np.testing.assert_array_equal(got.data, tile.image)
    assert got.valid.all()
    gt = read_ground_truth(ground_truth_path(city))
    assert gt.crs.to_epsg() == 2263
    assert sorted(gt["source_patch"]) == [f"{TILE}_00", f"{TILE}_00,{TILE}_01"]
    for line, src in zip(tile.lines, tile.line_sources):
        match = gt[gt["source_patch"] == ",".join(src)].geometry.iloc[0]
        np.testing.assert_allclose(np.asarray(match.coords), np.asarray(line.coords))
    assert (gt["tile_id"] == TILE).all()


def test_pil_written_patches_keep_nir_zero_pixels_valid(tmp_path):
    """The benchmark saved patches with PIL, which flags band 4 (NIR) as alpha; NIR 0 is still data."""
    Image = pytest.importorskip("PIL.Image")
    make_dataset(tmp_path, splits=1)
    pixels = patch_pixels(0, 0)
    pixels[3, :5, :] = 0
    path = tmp_path / "dataset" / "cropped_tiff" / f"{TILE}_00.tiff"
    Image.fromarray(np.moveaxis(pixels, 0, -1)).save(path)
    report = import_quiet(tmp_path, tmp_path / "out", splits=1)
    with Mosaic.open(tiles_dir(report["tiles"][TILE]["city_dir"])) as mosaic:
        got = mosaic.read(mosaic.window)
    assert got.valid.all()
    np.testing.assert_array_equal(got.data, pixels)


# -- placement of tiles from their ids -------------------------------------------------------------
def test_tile_ids_decode_to_the_2500_ft_grid_by_hand():
    from csboundary.data.topo_boundary import placed_transform, tile_origin_ft

    assert tile_origin_ft("987217") == (987_500.0, 217_500.0)  # the one grid line within each 1000 ft
    assert tile_origin_ft("990215") == (990_000.0, 215_000.0)
    assert tile_origin_ft("002210") == (1_002_500.0, 210_000.0)  # eastings past 1,000,000 ft wrap
    assert tile_origin_ft("986217") is None  # no grid line in 986,000-987,000: not the pattern
    assert tile_origin_ft("12345") is None
    t = placed_transform("987217")
    assert (t.a, t.e, t.c, t.f) == (0.5, -0.5, 987_500.0, 217_500.0 + 2500.0)  # north-up, top-left corner


def _placed_tile(tile_id: str, transform: Affine, chains: list[np.ndarray], size: int = 40):
    from csboundary.data.topo_boundary import AssembledTile

    return AssembledTile(
        tile_id,
        np.zeros((4, 1, 1), np.uint8),
        np.zeros((1, 1), bool),
        transform,
        "EPSG:2263",
        False,
        size // 2,
        2,
        {},
        [],
        [],
        chains=chains,
        placed=True,
    )


def test_boundaries_continue_across_correctly_placed_tiles_and_not_across_misplaced_ones():
    from csboundary.data.topo_boundary import border_continuity, join_tiles

    west = _placed_tile("a", Affine(0.5, 0, 1000.0, 0, -0.5, 2000.0), [np.array([[10.0, 5.0], [10.0, 39.0]])])
    east = _placed_tile(
        "b", Affine(0.5, 0, 1020.0, 0, -0.5, 2000.0), [np.array([[10.0, 0.0], [10.0, 30.0]])]
    )  # 40 px = 20 ft east
    report = border_continuity([west, east])
    assert report == {"border_ends": 2, "matched": 2, "share": 1.0}
    frame, lines, sources = join_tiles([west, east])
    assert len(lines) == 1 and sorted(sources[0]) == ["a", "b"]
    assert lines[0].length == pytest.approx((70 - 5) * 0.5, abs=0.6)  # one boundary from col 5 to col 70, in feet
    shifted = _placed_tile("b", Affine(0.5, 0, 1020.0, 0, -0.5, 1990.0), east.chains)  # 20 px too far south
    assert border_continuity([west, shifted])["share"] == 0.0


def test_import_places_tiles_from_ids_and_writes_a_city_per_split(tmp_path):
    root = make_dataset(
        tmp_path / "src", tile="987217", labels={(0, 0): [[[5, 0], [5, 19]]], (0, 1): [[[5, 0], [5, 10]]]}
    )
    report = import_topo_boundary(root, tmp_path / "out", patch_size=PS, splits=2, progress=False)
    assert report["tiles"]["987217"]["placed_from_id"]
    ((split, city),) = report["split_cities"].items()
    meta = read_meta(city["city_dir"])
    assert meta["tile_ids"] == ["987217"] and meta["crs"] == "EPSG:2263"
    with Mosaic.open(tiles_dir(city["city_dir"])) as mosaic:  # the linked tile, on the map
        assert (mosaic.transform.c, mosaic.transform.f) == (987_500.0, 217_500.0 + 2 * PS * 0.5)
    gt = read_ground_truth(ground_truth_path(city["city_dir"]))
    assert len(gt) == 1 and gt.total_bounds[0] >= 987_500.0  # the patch-split boundary, re-joined, in feet
    plain = import_topo_boundary(root, tmp_path / "plain", patch_size=PS, splits=2, progress=False, placement=False)
    assert plain["split_cities"] == {} and not plain["tiles"]["987217"]["placed_from_id"]
