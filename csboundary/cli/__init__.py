"""The ``csboundary`` command line."""
