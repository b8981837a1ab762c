"""csboundary: city-scale road-boundary graphs from aerial imagery.

After Xu et al., "csBoundary: City-scale Road-boundary Detection in Aerial Images for
High-definition Maps", RA-L 2022. The layers, each importing only those below it: ``errors`` and
``config``; ``data`` (imagery, synthetic cities, the patch grid); ``graph`` (the boundary graph,
its settings, stitching); ``labels``, ``metrics``, ``viz``; ``models`` (the FPN, AfANet, baselines,
training); ``pipeline`` (running a city, its outputs, training workflows, evaluation); ``api``
and ``cli`` on top. The Python API (docs/api.md) is importable from here: ``csboundary.predict``,
``csboundary.load_model`` and the rest of :data:`__all__` (the one list of the API's names, which
``csboundary.api`` shares), loaded on first use so that ``import csboundary`` stays light.
"""

__version__ = "0.1.0"

__all__ = [
    "GraphOverrides",
    "GraphSettings",
    "PredictionOptions",
    "adapt",
    "evaluate",
    "evaluate_model",
    "evaluate_set",
    "finetune",
    "load_model",
    "predict",
    "predict_patch",
    "read_prediction",
]


def __getattr__(name: str):
    if name in __all__:
        from csboundary import api

        return getattr(api, name)
    raise AttributeError(f"module 'csboundary' has no attribute {name!r}")
