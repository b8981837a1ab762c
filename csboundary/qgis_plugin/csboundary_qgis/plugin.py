"""Registers the Processing provider; the plugin has no window of its own (its algorithms are in
the Processing Toolbox, in models and in qgis_process)."""

from qgis.core import QgsApplication

from .provider import CsboundaryProvider


class CsboundaryPlugin:
    def __init__(self, iface):
        self.iface = iface
        self.provider = None

    def initProcessing(self):  # noqa: N802 (QGIS's name; qgis_process calls it without initGui)
        self.provider = CsboundaryProvider()
        QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802
        self.initProcessing()

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
