"""Issue 65: a folder of tiles kilometres apart is predicted, mapped and reviewed at the cost of
its imagery, not of its bounding box (data/footprint.py)."""

from __future__ import annotations

import json

import numpy as np
import rasterio
from affine import Affine
from test_hostile_inputs import GSD, UTM, tiny_bundle

from csboundary.data.geotiff import write_geotiff
from helpers import run_cli

APART_PX = 40_000  # 12 km at 0.3 m: a box of 1.6 G pixels for 0.18 M pixels of imagery


def test_scattered_tiles_plan_only_their_patches_and_write_sparse_maps(tmp_path):
    folder = tmp_path / "tiles"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k, (col, row) in enumerate([(0, 0), (APART_PX, 0), (0, APART_PX)]):
        write_geotiff(
            folder / f"t{k}.tif",
            rng.integers(0, 200, (4, 250, 250)).astype(np.uint8),
            Affine(GSD, 0, 500000 + col * GSD, 0, -GSD, 4400000 - row * GSD),
            UTM,
        )
    bundle = tiny_bundle(tmp_path / "bundle.pt")
    out = tmp_path / "out"
    done = run_cli(
        "predict",
        str(folder),
        "--out",
        str(out),
        "--weights",
        str(bundle),
        "--device",
        "cpu",
        "--quiet",
        "--write-maps",
    )
    assert done.returncode == 0, done.stderr
    assert (
        "3 patches under 3 groups of tiles kilometres apart, of a 41x41 grid" in done.stderr
    )  # 1,681 patches in the box
    summary = json.loads((out / "summary.json").read_text())
    assert summary["patches"] == 3 and summary["patches_without_imagery"] == 0
    assert summary["area_km2"] == round(3 * (250 * GSD) ** 2 / 1e6, 6)  # the imagery's area, not the box's
    with rasterio.open(out / "maps.tif") as maps:
        assert (maps.width, maps.height) == (APART_PX + 250, APART_PX + 250)
        assert maps.read(2, window=((0, 250), (0, 250))).any()  # the tiles' maps are there, the rest never written
    review = run_cli("review", str(out), "--out", str(tmp_path / "page"), "--quiet")
    assert review.returncode == 0, review.stderr
    assert len(list((tmp_path / "page" / "tiles" / "0").glob("*.jpg"))) == 3  # one 512 px tile over each 250 px tile
