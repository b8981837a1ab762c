"""The "csboundary" Processing provider and its one setting: the csboundary command to run."""

import os

from qgis.core import QgsApplication, QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

from .algorithms import ALGORITHMS
from .command import COMMAND_SETTING
from .runner import COMMAND_ENV


class CsboundaryProvider(QgsProcessingProvider):
    def load(self):
        try:
            from processing.core.ProcessingConfig import ProcessingConfig, Setting
        except ImportError:  # Processing's Python plugin absent: the environment variable or PATH still work
            pass
        else:
            ProcessingConfig.settingIcons[self.name()] = self.icon()
            ProcessingConfig.addSetting(
                Setting(
                    self.name(),
                    COMMAND_SETTING,
                    f"csboundary command (the csboundary executable of its environment; empty: ${COMMAND_ENV}, then PATH)",
                    "",
                    valuetype=Setting.FILE,
                )
            )
            ProcessingConfig.readSettings()
        self.refreshAlgorithms()
        return True

    def unload(self):
        try:
            from processing.core.ProcessingConfig import ProcessingConfig
        except ImportError:
            return
        if COMMAND_SETTING in ProcessingConfig.settings:
            ProcessingConfig.removeSetting(COMMAND_SETTING)

    def loadAlgorithms(self):  # noqa: N802
        for algorithm in ALGORITHMS:
            self.addAlgorithm(algorithm())

    def id(self):
        return "csboundary"

    def name(self):
        return "csboundary"

    def longName(self):  # noqa: N802
        return "csboundary: road boundaries from aerial imagery"

    def icon(self):
        path = os.path.join(os.path.dirname(__file__), "icon.svg")
        return QIcon(path) if os.path.exists(path) else QgsApplication.getThemeIcon("/processingAlgorithm.svg")
