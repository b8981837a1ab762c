"""Read the Topo-boundary dataset (NYC) and turn it into csboundary city directories.

The benchmark cuts every 5000x5000 orthophoto tile into 25 patches ``TTTTTT_RC.tiff`` (6-digit
tile id, R = row block from the top, C = column block) with per-patch boundary labels
``labels/dense_seq/{id}.json`` in patch pixels ``[row, col]``. csBoundary works on whole tiles and
vector ground truth, so this package puts the patches back together, re-joins the boundaries that
the cut split at patch borders, and writes each tile as a city (see :mod:`csboundary.data.city_layout`).

One module per job: :mod:`.files` reads the dataset's files, :mod:`.placement` puts a tile on
the map, :mod:`.boundaries` joins and smooths boundary pixel chains, :mod:`.tiles` assembles
one tile, :mod:`.seams` joins placed tiles, :mod:`.cities` writes the cities. Everything is
importable from this package.

Choices, because the format leaves them open:

* Images and labels are found by searching the given root recursively, because users unpack the
  archives into different folders (the benchmark uses ``dataset/cropped_tiff`` and
  ``dataset/labels``).
* The benchmark's patches were saved without georeference (the tile id is the only link to the
  map). A georeference in the files is used when present; otherwise the tile is placed at
  0.5 US ft/px in EPSG:2263 with its top-left corner at (0, 0) and a warning.
* Every pixel of a present patch is valid. Patch masks are ignored on purpose: the benchmark's
  TIFFs mark band 4 (NIR) as alpha, so a mask derived from it would drop every pixel with NIR 0.
* Missing patches (the benchmark dropped many, e.g. all ``pretrain`` images) are masked invalid and
  reported. Their labels, when present, are still imported: ground truth describes the ground,
  not the imagery, and consumers mask by the tile's validity.
* Patch size and split count are parameters (defaults 1000 and 5) so tests can fabricate tiny
  files in exactly the same format.
"""

from csboundary.data.topo_boundary.boundaries import (
    JOIN_TOLERANCE,
    SIMPLIFY_PX,
    SMOOTH_PIXELS,
    Piece,
    join_pieces,
    pixels_to_line,
)
from csboundary.data.topo_boundary.cities import (
    SOURCE,
    import_topo_boundary,
    tile_file_name,
    tile_split,
    write_split_cities,
    write_tile_city,
)
from csboundary.data.topo_boundary.files import (
    LABEL_DIR,
    LABEL_MARGIN,
    PATCH_SIZE,
    SPLIT_FILE,
    SPLITS,
    Patch,
    TopoBoundaryIndex,
    clip_to_patch,
    parse_patch_id,
    patch_id,
    read_data_split,
    read_dense_seq,
    read_patch,
    scan,
)
from csboundary.data.topo_boundary.placement import (
    FALLBACK_CRS,
    FALLBACK_GSD,
    GRID_FT,
    fallback_transform,
    placed_transform,
    tile_georeference,
    tile_origin_ft,
)
from csboundary.data.topo_boundary.seams import border_continuity, join_tiles
from csboundary.data.topo_boundary.tiles import AssembledTile, assemble_tile

__all__ = [
    "FALLBACK_CRS",
    "FALLBACK_GSD",
    "GRID_FT",
    "JOIN_TOLERANCE",
    "LABEL_DIR",
    "LABEL_MARGIN",
    "PATCH_SIZE",
    "SIMPLIFY_PX",
    "SMOOTH_PIXELS",
    "SOURCE",
    "SPLITS",
    "SPLIT_FILE",
    "AssembledTile",
    "Patch",
    "Piece",
    "TopoBoundaryIndex",
    "assemble_tile",
    "border_continuity",
    "clip_to_patch",
    "fallback_transform",
    "import_topo_boundary",
    "join_pieces",
    "join_tiles",
    "parse_patch_id",
    "patch_id",
    "pixels_to_line",
    "placed_transform",
    "read_data_split",
    "read_dense_seq",
    "read_patch",
    "scan",
    "tile_file_name",
    "tile_georeference",
    "tile_origin_ft",
    "tile_split",
    "write_split_cities",
    "write_tile_city",
]
