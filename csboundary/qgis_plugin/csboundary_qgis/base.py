"""What every Processing algorithm shares: the csboundary command's run (QGIS's progress bar, log
and cancel), the parameters several algorithms take and the command-line options they become, and
the checks of their inputs (folders, predictions, imagery files)."""

import os

from qgis.core import (
    QgsProcessingAlgorithm,
    QgsProcessingException,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFile,
    QgsProcessingParameterFileDestination,
    QgsProcessingParameterFolderDestination,
    QgsProcessingParameterNumber,
    QgsProcessingUtils,
)

from . import runner
from .command import configured_command

DEVICES = ("auto", "cpu", "cuda")


class CsboundaryAlgorithm(QgsProcessingAlgorithm):
    """What every algorithm shares: the command's run with QGIS's progress bar and cancel."""

    NAME = ""
    TITLE = ""
    HELP = ""

    def createInstance(self):  # noqa: N802 (QGIS's names throughout)
        return type(self)()

    def name(self):
        return self.NAME

    def displayName(self):  # noqa: N802
        return self.TITLE

    def shortHelpString(self):  # noqa: N802
        return self.HELP + (
            "<p>Runs the csboundary command of the environment named under Settings > Options > "
            "Processing > Providers > csboundary (or $CSBOUNDARY_COMMAND, or the one on PATH).</p>"
        )

    def csboundary(self, args, feedback):
        """Run ``csboundary args``: its bars in QGIS's progress bar, its lines in the log, cancel
        stops it; a failure is one QgsProcessingException line."""
        try:
            command = runner.find_command(configured_command())
            feedback.pushInfo(f"{runner.check_command(command)} ({command})")
            feedback.pushCommandInfo(" ".join([command, *args]))
            progress = runner.Progress(
                stage=feedback.setProgressText,
                percent=feedback.setProgress,
                line=feedback.pushConsoleInfo,
                canceled=feedback.isCanceled,
            )
            return runner.run(command, list(args), progress)
        except runner.Canceled:
            raise QgsProcessingException(
                "canceled: csboundary was stopped (a prediction keeps its finished patches: "
                "run it again into the same folder to continue)"
            ) from None
        except runner.CommandError as exc:
            raise QgsProcessingException(f"csboundary: {exc}") from None

    def engine_parameters(self):
        self.addParameter(
            QgsProcessingParameterFile(
                "WEIGHTS", "Weights bundle (empty: the shipped weights)", extension="pt", optional=True
            )
        )
        self.addParameter(QgsProcessingParameterEnum("DEVICE", "Device", options=list(DEVICES), defaultValue=0))

    def engine_args(self, parameters, context):
        args = ["--device", DEVICES[self.parameterAsEnum(parameters, "DEVICE", context)]]
        weights = self.parameterAsFile(parameters, "WEIGHTS", context)
        return args + (["--weights", weights] if weights else [])

    def folder(self, parameters, name, context):
        path = self.parameterAsFile(parameters, name, context)
        if not path or not os.path.isdir(path):
            raise QgsProcessingException(f"{path or name}: not a folder")
        return path

    def min_confidence_parameter(self):
        self.addParameter(
            QgsProcessingParameterNumber(
                "MIN_CONFIDENCE",
                "Leave out edges less sure than",
                QgsProcessingParameterNumber.Double,
                0.0,
                minValue=0.0,
                maxValue=1.0,
            )
        )

    def min_confidence_args(self, parameters, context):
        min_confidence = self.parameterAsDouble(parameters, "MIN_CONFIDENCE", context)
        return ["--min-confidence", repr(min_confidence)] if min_confidence > 0 else []

    def training_parameters(self, fpn_steps, afanet_steps, afanet_label, afanet_min, output_label):
        """Fine-tune's and Adapt's budget, engine, optional work folder and weights to write."""
        self.addParameter(
            QgsProcessingParameterNumber(
                "FPN_STEPS", "FPN steps", QgsProcessingParameterNumber.Integer, fpn_steps, minValue=1
            )
        )
        self.addParameter(
            QgsProcessingParameterNumber(
                "AFANET_STEPS", afanet_label, QgsProcessingParameterNumber.Integer, afanet_steps, minValue=afanet_min
            )
        )
        self.engine_parameters()
        self.addParameter(
            QgsProcessingParameterFolderDestination(
                "WORK", "Work folder (training runs; empty: beside the weights)", optional=True, createByDefault=False
            )
        )
        self.addParameter(QgsProcessingParameterFileDestination("OUTPUT", output_label, "Weights bundle (*.pt)"))

    def training_args(self, parameters, context):
        work = self.parameterAsString(parameters, "WORK", context) if parameters.get("WORK") else ""
        return [
            *(["--work", work] if work else []),
            "--fpn-steps",
            str(self.parameterAsInt(parameters, "FPN_STEPS", context)),
            "--afanet-steps",
            str(self.parameterAsInt(parameters, "AFANET_STEPS", context)),
            *self.engine_args(parameters, context),
        ]

    def kept(self, path, what, feedback):
        """Warn when ``path`` is in QGIS's temporary folder: deleted when QGIS closes, and a new
        one each run, so a canceled run could not be continued there."""
        temporary = os.path.normcase(os.path.realpath(QgsProcessingUtils.tempFolder()))
        if os.path.normcase(os.path.realpath(path)).startswith(temporary + os.sep):
            feedback.reportError(
                f"{what} is in QGIS's temporary folder ({path}): it is deleted when QGIS closes, and a canceled "
                "run can only be continued in the same folder; give a folder of your own to keep it",
                False,
            )
        return path

    def prediction(self, parameters, context):
        """A predict output folder (its graph.json must be there)."""
        path = self.folder(parameters, "PREDICTION", context)
        if not os.path.isfile(os.path.join(path, "graph.json")):
            raise QgsProcessingException(
                f"{path}: not a csboundary prediction (no graph.json): choose a Detect output folder"
            )
        return path


def imagery_files(algorithm, parameters, name, context):
    """The files behind raster layers; a layer that is not a local raster file is refused, with the way out."""
    layers = algorithm.parameterAsLayerList(parameters, name, context)
    if not layers:
        raise QgsProcessingException("no imagery given")
    files = []
    for layer in layers:
        path = layer.source().split("|")[0]
        if layer.providerType() != "gdal" or not os.path.isfile(path):
            raise QgsProcessingException(
                f"{layer.name()}: not a local raster file; save it as a GeoTIFF first (Raster > Conversion > Translate)"
            )
        files.append(path)
    return files
