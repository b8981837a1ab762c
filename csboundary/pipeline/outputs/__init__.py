"""What a prediction is written as and turned into: the vector files (``prediction_files``),
the maps as a GeoTIFF, a Lanelet2 map, the review page and reviewed edits, pictures."""
