"""Imagery and ground truth: raster mosaics, the city-wide patch grid, the synthetic city, Topo-boundary."""
