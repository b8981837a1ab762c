"""Copy a city with its tiles reduced to RGB (bands 1-3): how a model is scored on RGB-only imagery.

Usage: .venv/bin/python scripts/rgb_city.py CITY OUT
"""

import shutil
import sys
from pathlib import Path

import rasterio

from csboundary.data import city_layout
from csboundary.data.geotiff import write_geotiff

src, dst = Path(sys.argv[1]), Path(sys.argv[2])
city_layout.begin_city(dst)
for tile in sorted(city_layout.tiles_dir(src).glob("*.tif")):
    with rasterio.open(tile) as ds:
        write_geotiff(city_layout.tiles_dir(dst) / tile.name, ds.read([1, 2, 3]), ds.transform, ds.crs.to_string())
shutil.copy(city_layout.ground_truth_path(src), city_layout.ground_truth_path(dst))
meta = city_layout.read_meta(src)
meta["notes"] = f"RGB copy of {src} (NIR dropped) made by scripts/rgb_city.py"
city_layout.write_meta(dst, meta)
