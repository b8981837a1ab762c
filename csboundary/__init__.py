"""csboundary: city-scale road-boundary graphs from aerial imagery.

After Xu et al., "csBoundary: City-scale Road-boundary Detection in Aerial Images for
High-definition Maps", RA-L 2022. Stages live in sub-packages named after the pipeline:
``data`` (imagery, synthetic city, patch grid), ``viz`` (overlays), ``cli``.
"""

__version__ = "0.1.0"
