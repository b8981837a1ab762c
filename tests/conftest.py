"""Shared fixtures: small aligned GeoTIFF tiles fabricated with rasterio in a temporary directory.

The test folders mirror the package (tests/data for csboundary/data, ...); this folder is put on
the import path so every test file can import ``helpers`` and this module.

The default mosaic is 2x2 tiles of 60x40 px, 4-band uint8, EPSG:32618, 0.5 m/px, with its
top-left corner at (500000, 4400000). The stitched full array is returned alongside the files so
tests can compare any window read from the mosaic against a plain numpy slice.
"""

from __future__ import annotations

import os
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning

sys.path.insert(0, str(Path(__file__).parent))

if os.environ.get("PYTEST_XDIST_WORKER"):
    # the suite runs on one worker per core (pytest-xdist): one thread each, in the tests and in
    # the commands they start, so two workers do not fight over the cores (a test module that set
    # torch's threads at import would set them for every test of every worker: each collects all)
    os.environ.setdefault("OMP_NUM_THREADS", "1")

CRS = "EPSG:32618"
GSD = 0.5
ORIGIN = (500000.0, 4400000.0)  # world (x, y) of the mosaic's top-left corner
TILE_W, TILE_H = 60, 40


def write_raster(path, array, transform=None, crs=CRS, **profile) -> Path:
    """Write ``array`` (bands, rows, cols) with rasterio; ``transform=None`` writes no georeference."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    bands, rows, cols = array.shape
    kwargs = dict(driver="GTiff", width=cols, height=rows, count=bands, dtype=array.dtype.name, crs=crs)
    if transform is not None:
        kwargs["transform"] = transform
    kwargs.update(profile)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", **kwargs) as dst:
            dst.write(array)
    return path


@dataclass
class TileSet:
    """Tiles on disk plus the ground truth they were cut from."""

    directory: Path
    paths: list[Path]  # row-major: paths[r * nx + c] is tile (r, c)
    full: np.ndarray  # (4, ny * tile_h, nx * tile_w) stitched pixels
    transform: Affine  # of the whole mosaic
    crs: str
    tile_w: int
    tile_h: int
    nx: int
    ny: int

    def tile_path(self, r: int, c: int) -> Path:
        return self.paths[r * self.nx + c]


def make_tileset(
    directory: Path,
    nx: int = 2,
    ny: int = 2,
    tile_w: int = TILE_W,
    tile_h: int = TILE_H,
    gsd: float = GSD,
    origin: tuple[float, float] = ORIGIN,
    crs: str = CRS,
    seed: int = 0,
) -> TileSet:
    rng = np.random.default_rng(seed)
    full = rng.integers(0, 256, size=(4, ny * tile_h, nx * tile_w), dtype=np.uint8)
    x0, y0 = origin
    paths = []
    for r in range(ny):
        for c in range(nx):
            transform = Affine(gsd, 0.0, x0 + c * tile_w * gsd, 0.0, -gsd, y0 - r * tile_h * gsd)
            part = full[:, r * tile_h : (r + 1) * tile_h, c * tile_w : (c + 1) * tile_w]
            paths.append(write_raster(directory / f"tile_r{r}_c{c}.tif", part, transform, crs))
    transform = Affine(gsd, 0.0, x0, 0.0, -gsd, y0)
    return TileSet(directory, paths, full, transform, crs, tile_w, tile_h, nx, ny)


@pytest.fixture
def tiles(tmp_path) -> TileSet:
    """A fresh 2x2 mosaic of 60x40 px tiles in its own directory (tests may add files next to it)."""
    return make_tileset(tmp_path / "tiles")


@pytest.fixture(scope="session")
def shared_tiles(tmp_path_factory) -> TileSet:
    """The same 2x2 mosaic, built once per session, for read-only use (e.g. inside hypothesis tests)."""
    return make_tileset(tmp_path_factory.mktemp("shared") / "tiles")


@pytest.fixture
def tile_factory(tmp_path):
    """``tile_factory(name, **make_tileset kwargs)`` builds another tile set under tmp_path/name."""

    def factory(name: str, **kwargs) -> TileSet:
        return make_tileset(tmp_path / name, **kwargs)

    return factory


@pytest.fixture
def write_tif():
    """The :func:`write_raster` helper, for tests that fabricate one-off files."""
    return write_raster


@pytest.fixture(scope="session", autouse=True)
def onnx_cache(tmp_path_factory):
    """The ONNX export cache of the whole run (``$CSBOUNDARY_CACHE``, which the commands the
    tests start inherit): never the user's ~/.cache. One folder for every pytest-xdist worker of
    the run, so the shipped networks are exported (and quantized) at most once per run, in the
    first test that needs them; kept when the caller set ``CSBOUNDARY_CACHE`` (a CI cache kept
    between runs). A test that changes how exports are made uses a folder of its own."""
    from csboundary.models.onnx_session import CACHE_ENV

    if os.environ.get(CACHE_ENV):
        yield Path(os.environ[CACHE_ENV])
        return
    folder = shared_folder(tmp_path_factory) / "onnx-cache"
    folder.mkdir(parents=True, exist_ok=True)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(CACHE_ENV, str(folder))
        yield folder


def shared_folder(tmp_path_factory) -> Path:
    """The folder of the whole test run, above the pytest-xdist workers' own (theirs alone
    without xdist): what is made there once is shared by every worker."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory) -> Path:
    """``csboundary demo`` run once per test run (the shipped model on the demo city), by the
    first worker that needs it while the others wait on a lock: its folder holds ``city/`` and
    ``prediction/``. Read-only: copy what a test changes."""
    import fcntl

    from helpers import run_cli

    shared = shared_folder(tmp_path_factory)
    out = shared / "demo-run" / "demo"
    with open(shared / "demo-run.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (out / "scores.json").exists():
            done = run_cli("demo", "--out", str(out), "--device", "cpu", timeout=600)
            assert done.returncode == 0, done.stderr
            (shared / "demo-run" / "stdout.txt").write_text(done.stdout)  # what the command printed
    return out
