"""City-scale scores of a bundle at another vertex-extraction threshold (keypoint probability),
on the Ottawa set and/or labelled cities: how the model card's threshold rows were measured.

    python scripts/probe_vertex_threshold.py BUNDLE THRESHOLD /tmp/ottawa data/cities/test-grid-s7-2x2-2000 ...

A folder holding a ``set.json`` (or named like the Ottawa set) is scored as a set (mean over its
cities), any other folder as one city.
"""

import dataclasses
import sys
from pathlib import Path

from csboundary.labels.mask_import import SET_FILE
from csboundary.pipeline.evaluate_set import evaluate_city, evaluate_set
from csboundary.pipeline.patch import load_predictor

bundle, threshold = sys.argv[1], float(sys.argv[2])
predictor = load_predictor(bundle, device="cpu")
predictor.vertices = dataclasses.replace(predictor.vertices, threshold=threshold)
for target in sys.argv[3:]:
    if (Path(target) / SET_FILE).exists():
        metrics = evaluate_set(target, predictor, progress=False)["mean"]
    else:
        metrics = evaluate_city(target, predictor, progress=False)["city"]["metrics"]
    print(Path(bundle).name, threshold, Path(target).name, {k: round(metrics[k], 3) for k in ("precision@5", "recall@5", "f1@5", "apls", "tlts")}, flush=True)
