"""Check that the city graph made block by block is the one made in one pass, file for file, on
real predictions of labelled cities (the demo city and the synthetic test cities).

    python scripts/check_city_blocks.py data/cities/test-s7-2x2-2000 ... [--weights W] [--blocks 1 2 8]

Each city is predicted once with the shipped weights (the FPN, AfANet and the edge confidence, in
memory); then its city graph is made and written (GeoPackage, GeoJSON, graph.json) in one pass
and block by block, for every block size, and the files compared: sha256 of graph.json and the
GeoJSON, every feature of both GeoPackage layers. Prints one line per city and block size.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import tempfile
from pathlib import Path

import pyogrio

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from csboundary.data import city_layout  # noqa: E402
from csboundary.data.model_view import mosaic_units  # noqa: E402
from csboundary.data.raster import Mosaic  # noqa: E402
from csboundary.graph.stitching import StitchConfig  # noqa: E402
from csboundary.pipeline.outputs.prediction_files import GraphWriter  # noqa: E402
from csboundary.pipeline.prediction.city import predict_city  # noqa: E402
from csboundary.pipeline.prediction.city_blocks import CityGraphRecipe, stream_city_graph  # noqa: E402
from csboundary.pipeline.prediction.city_job import DEFAULT_CHANNELS  # noqa: E402
from csboundary.pipeline.prediction.edge_scoring import core_sampler  # noqa: E402
from csboundary.pipeline.prediction.options import PredictionOptions  # noqa: E402
from csboundary.pipeline.prediction.patch import load_predictor  # noqa: E402
from csboundary.pipeline.prediction.run_store import RunStore  # noqa: E402


def written(result, store, model, block: int, one_pass: bool, folder: Path) -> dict:
    grid = result.grid
    recipe = CityGraphRecipe(
        StitchConfig(),
        result.graph.crs,
        model.settings.min_fragment_px,
        model.settings.attach_px,
        model.confidence,
        model.settings.min_confidence,
        True,
        block=block,
    )
    files = {
        "gpkg": folder / "boundaries.gpkg",
        "geojson": folder / "boundaries.geojson",
        "graph_json": folder / "graph.json",
    }
    writer = GraphWriter(files, result.graph.crs, grid.transform, mosaic_units(store.mosaic))
    sample = core_sampler(grid, store.load_core, store.channels or DEFAULT_CHANNELS)
    stream_city_graph(result.patch_graphs.__getitem__, grid, recipe, sample, writer.add, one_pass=one_pass)
    counts = writer.close()
    layers = {
        f"layer {layer}": pyogrio.read_dataframe(files["gpkg"], layer=layer).to_wkt().to_csv()
        for layer in ("road_boundaries", "edges")
    }
    return {
        "edges": counts["edges"],
        "boundaries": counts["boundaries"],
        **{name: hashlib.sha256(files[name].read_bytes()).hexdigest() for name in ("graph_json", "geojson")},
        **layers,
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("cities", nargs="+", type=Path)
    parser.add_argument("--weights", type=Path, default=None)
    parser.add_argument("--blocks", type=int, nargs="+", default=[1, 2, 8])
    args = parser.parse_args()
    model = load_predictor(args.weights, "cpu")
    failed = 0
    for city in args.cities:
        with Mosaic.open(city_layout.tiles_dir(city)) as mosaic:
            store = RunStore()
            result = predict_city(mosaic, model, PredictionOptions(progress=False), store=store)
            store.mosaic = mosaic
            for block in args.blocks:
                with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
                    one = written(result, store, model, block, True, Path(a))
                    blocks = written(result, store, model, block, False, Path(b))
                same = one == blocks
                failed += not same
                print(
                    f"{city.name}: {result.grid.shape[0]}x{result.grid.shape[1]} patches, block {block}: {one['edges']} edges, "
                    f"{one['boundaries']} boundaries; blocks {'==' if same else '!='} one pass"
                    + ("" if same else f" ({', '.join(k for k in one if one[k] != blocks[k])} differ)"),
                    flush=True,
                )
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
