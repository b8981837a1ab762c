"""Scoring models: a labelled set city by city, the paper's benchmark of every method, and the
ground truth as a model (the pipeline's own upper bound)."""
