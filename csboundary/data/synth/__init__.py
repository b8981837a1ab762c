"""A synthetic aerial city with exact vector road-boundary ground truth.

The real benchmark imagery cannot be downloaded here, so this city is what the demo, the tests
and training use. ``streets`` builds the street network and the roadway polygon (hence the
ground truth), ``scene`` places what stands on and beside the roads, ``render`` paints tiles,
``camera`` gives them the city's photographic look, ``city`` writes a city directory.
``streets`` and ``scene`` run their recipes from smaller modules with one job each, named in
their docstrings.
"""
