"""The paper's baselines (Section V-D), one per family of methods, behind the same two doors as
csBoundary: a training function ``train(config, out_dir, device, resume, progress) -> Path`` and
a :class:`~csboundary.models.patch_model.PatchModel` (``load(path, device)``, ``patch_maps``,
``extract``, ``connect``), so the city pipeline (map averaging, stitching) and the metrics treat
every method alike.

* ``orientation-refine`` (segmentation family, Batra et al. 2019): segmentation + orientation
  network and a refinement network, then threshold -> skeleton -> graph.
* ``sat2graph`` (graph-generation family, He et al. 2020): the 19-channel graph tensor, decoded on
  csBoundary's extracted vertices, as in the paper.
* ``icurb`` (iterative family, Xu et al. 2021): an agent that grows each boundary vertex by vertex
  from the patch border, trained by imitation with DAgger-style aggregation.
"""

from __future__ import annotations

from importlib import import_module

METHODS = {
    "orientation-refine": "csboundary.models.baselines.orientation_refine",
    "sat2graph": "csboundary.models.baselines.sat2graph",
    "icurb": "csboundary.models.baselines.icurb",
}


def baseline_module(name: str):
    """The module implementing baseline ``name`` (its ``train`` function and ``Model`` class)."""
    if name not in METHODS:
        raise ValueError(f"unknown baseline {name!r}; choose from {', '.join(METHODS)}")
    return import_module(METHODS[name])
