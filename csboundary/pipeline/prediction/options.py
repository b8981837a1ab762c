"""How a city is predicted, apart from what it is predicted with: one frozen object that travels
from the command line (or the Python API) through the prediction job to the city run, so no
layer repeats the options by hand.

What the model computes on a window is its own (:class:`~csboundary.graph.settings.GraphSettings`,
read from the weights); these are the run's: how the imagery is read and cut, how the work is
spread, how patch graphs become the city graph, and which files are written.
"""

from __future__ import annotations

from dataclasses import dataclass

from csboundary.data.grid import GridConfig
from csboundary.graph.stitching import StitchConfig
from csboundary.pipeline.prediction.city_blocks import BLOCK


@dataclass(frozen=True)
class PredictionOptions:
    """``gsd``: pixel size in metres of imagery without a CRS. ``grid``: patch core and margin;
    ``batch_size``: patches per FPN batch. ``threads``: torch threads per process (None: all
    cores, or cores / workers); ``scheduler`` (a Dask address) or ``workers`` (a local Dask
    cluster of that many processes) spread the patches. ``stitch``: how patch graphs join;
    ``block`` (patches) and ``one_pass``: how the city graph is streamed
    (:func:`~csboundary.pipeline.prediction.city_blocks.city_blocks`). ``write_maps``: also the
    stitched maps (maps.tif); ``lanelet2``: also a Lanelet2 map; ``restart``: discard an unfinished
    run instead of resuming it; ``progress``: progress bars."""

    gsd: float | None = None
    grid: GridConfig = GridConfig()
    batch_size: int = 1
    threads: int | None = None
    scheduler: str | None = None
    workers: int | None = None
    stitch: StitchConfig = StitchConfig()
    block: int = BLOCK
    one_pass: bool = False
    write_maps: bool = False
    lanelet2: bool = False
    restart: bool = False
    progress: bool = True

    def __post_init__(self) -> None:
        if self.batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {self.batch_size}")
        if self.scheduler and self.workers:
            raise ValueError("give a scheduler or a number of workers, not both")

    @property
    def distributed(self) -> bool:
        """Whether the patches are spread over Dask workers."""
        return bool(self.scheduler or self.workers)
