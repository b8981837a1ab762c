"""csboundary for QGIS: a Processing provider whose algorithms run the csboundary command of an
environment the user configures (docs/qgis.md)."""


def classFactory(iface):  # noqa: N802 (QGIS's name)
    from .plugin import CsboundaryPlugin

    return CsboundaryPlugin(iface)
