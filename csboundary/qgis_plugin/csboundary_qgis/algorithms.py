"""The Processing algorithms: each one a csboundary command, its options as parameters, its
output files loaded as layers. The work is done by the command (runner.py), so an algorithm
here only builds the command line and says what to load; what they share is in base.py, the
layers they load in layers.py."""

import json
import os
import tempfile

from qgis.core import (
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsProcessing,
    QgsProcessingException,
    QgsProcessingOutputFile,
    QgsProcessingOutputFolder,
    QgsProcessingOutputNumber,
    QgsProcessingOutputVectorLayer,
    QgsProcessingParameterBoolean,
    QgsProcessingParameterEnum,
    QgsProcessingParameterFile,
    QgsProcessingParameterFileDestination,
    QgsProcessingParameterFolderDestination,
    QgsProcessingParameterMultipleLayers,
    QgsProcessingParameterVectorLayer,
    QgsProject,
    QgsVectorFileWriter,
    QgsVectorLayer,
)

from .base import CsboundaryAlgorithm, imagery_files
from .layers import BOUNDARIES_LAYER, COMPLETE_LAYER, DRAFT_LAYER, HELD_BACK_LAYER, REVIEW_GPKG, load, load_review

ENGINES = ("auto", "torch", "onnx")


def prediction_crs(prediction):
    """The CRS a prediction was made in (its summary.json, small, rather than its graph.json)."""
    try:
        with open(os.path.join(prediction, "summary.json")) as file:
            return QgsCoordinateReferenceSystem(str(json.load(file).get("crs") or ""))
    except (OSError, ValueError):
        return QgsCoordinateReferenceSystem()


class Detect(CsboundaryAlgorithm):
    NAME = "detect"
    TITLE = "Detect road boundaries"
    HELP = (
        "<p>Predicts the road-boundary graph of aerial imagery (one or more GeoTIFF tiles of one mosaic) with "
        "<code>csboundary predict</code>, and loads the boundaries and the review layers, coloured by the "
        "calibrated confidence of each boundary: the least sure in red.</p>"
        "<p>To review: edit the <i>boundaries to review</i> layer of review.gpkg, a boundary per feature (delete "
        "false ones, split one and delete a part, move vertices, draw missing boundaries) and draw the areas you "
        "checked in its <i>complete</i> layer, then run Apply review. Boundaries not worth a look (their expected "
        "review cost exceeds what they save) are in the hidden <i>held back</i> layer; inside an area you mark "
        "complete, those you leave there are deleted (copy one into the boundaries layer to keep it).</p>"
        "<p>An interrupted or canceled run continues where it stopped when run again into the same output folder.</p>"
    )

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(
            QgsProcessingParameterMultipleLayers(
                "INPUT", "Aerial imagery (GeoTIFF tiles of one mosaic)", QgsProcessing.TypeRaster
            )
        )
        self.addParameter(QgsProcessingParameterEnum("ENGINE", "Engine", options=list(ENGINES), defaultValue=0))
        self.min_confidence_parameter()
        self.engine_parameters()
        self.addParameter(QgsProcessingParameterFolderDestination("OUTPUT", "Prediction folder"))
        self.addOutput(QgsProcessingOutputVectorLayer("BOUNDARIES", "Road boundaries", QgsProcessing.TypeVectorLine))
        self.addOutput(
            QgsProcessingOutputVectorLayer("REVIEW_BOUNDARIES", "Boundaries to review", QgsProcessing.TypeVectorLine)
        )
        self.addOutput(
            QgsProcessingOutputVectorLayer(
                "REVIEW_HELD_BACK", "Held back from the review", QgsProcessing.TypeVectorLine
            )
        )
        self.addOutput(
            QgsProcessingOutputVectorLayer("REVIEW_COMPLETE", "Areas checked", QgsProcessing.TypeVectorPolygon)
        )
        self.addOutput(QgsProcessingOutputFile("GRAPH", "graph.json"))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        inputs = imagery_files(self, parameters, "INPUT", context)
        out = self.kept(self.parameterAsString(parameters, "OUTPUT", context), "The prediction", feedback)
        args = [
            "predict",
            *inputs,
            "--out",
            out,
            "--engine",
            ENGINES[self.parameterAsEnum(parameters, "ENGINE", context)],
        ]
        args += self.min_confidence_args(parameters, context)
        self.csboundary(args + self.engine_args(parameters, context), feedback)
        review = os.path.join(out, REVIEW_GPKG)
        if os.path.exists(
            review
        ):  # edits may be in it: never overwritten (Apply review refuses it if the graph changed since)
            feedback.pushWarning(f"{review} exists and is kept (it may hold your edits); delete it for a fresh one")
        else:
            self.csboundary(["review", out, "--gpkg", review, "--quiet"], feedback)
        results = {
            "OUTPUT": out,
            "GRAPH": os.path.join(out, "graph.json"),
            "BOUNDARIES": f"{os.path.join(out, 'boundaries.gpkg')}|layername={BOUNDARIES_LAYER}",
            "REVIEW_BOUNDARIES": f"{review}|layername={DRAFT_LAYER}",
            "REVIEW_HELD_BACK": f"{review}|layername={HELD_BACK_LAYER}",
            "REVIEW_COMPLETE": f"{review}|layername={COMPLETE_LAYER}",
        }
        load(context, results["BOUNDARIES"], "road boundaries", "BOUNDARIES", "boundaries")
        load_review(context, review, "REVIEW_BOUNDARIES", "REVIEW_HELD_BACK", "REVIEW_COMPLETE")
        return results


class Evaluate(CsboundaryAlgorithm):
    NAME = "evaluate"
    TITLE = "Evaluate against ground truth"
    HELP = (
        "<p>Relaxed precision, recall and F1 at 2, 5 and 10 px, APLS and TLTS of a prediction against a "
        "ground-truth line layer (<code>csboundary evaluate</code>; definitions in docs/metrics.md).</p>"
    )
    SCORES = (
        ("F1_5", "f1@5"),
        ("PRECISION_5", "precision@5"),
        ("RECALL_5", "recall@5"),
        ("F1_2", "f1@2"),
        ("F1_10", "f1@10"),
        ("APLS", "apls"),
        ("TLTS", "tlts"),
    )

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(
            QgsProcessingParameterFile("PREDICTION", "Prediction folder", QgsProcessingParameterFile.Folder)
        )
        self.addParameter(
            QgsProcessingParameterVectorLayer(
                "GROUND_TRUTH", "Ground-truth road boundaries", [QgsProcessing.TypeVectorLine]
            )
        )
        self.addParameter(QgsProcessingParameterFileDestination("OUTPUT", "Scores (JSON)", "JSON files (*.json)"))
        for key, label in self.SCORES:
            self.addOutput(QgsProcessingOutputNumber(key, label))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        prediction = self.prediction(parameters, context)
        layer = self.parameterAsVectorLayer(parameters, "GROUND_TRUTH", context)
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        with tempfile.TemporaryDirectory() as work:  # any layer (PostGIS, memory, a shapefile) as one GeoPackage
            ground_truth = os.path.join(work, "ground_truth.gpkg")
            options = QgsVectorFileWriter.SaveVectorOptions()
            options.driverName = "GPKG"
            crs = prediction_crs(prediction)
            if (
                crs.isValid() and layer.crs().isValid() and layer.crs() != crs
            ):  # in the prediction's CRS, as evaluate needs it
                options.ct = QgsCoordinateTransform(layer.crs(), crs, context.transformContext())
                feedback.pushInfo(
                    f"{layer.name()}: reprojected from {layer.crs().authid()} to the prediction's {crs.authid()}"
                )
            error = QgsVectorFileWriter.writeAsVectorFormatV3(layer, ground_truth, context.transformContext(), options)
            if error[0] != QgsVectorFileWriter.NoError:
                raise QgsProcessingException(f"{layer.name()}: could not be written for csboundary ({error[1]})")
            try:
                self.csboundary(
                    ["evaluate", os.path.join(prediction, "graph.json"), ground_truth, "--json", out], feedback
                )
            except QgsProcessingException as exc:  # the layer's name, not the temporary copy's path
                raise QgsProcessingException(str(exc).replace(ground_truth, layer.name())) from None
        with open(out) as file:
            scores = json.load(file)
        metrics = scores.get("metrics", scores)
        results = {"OUTPUT": out}
        for key, name in self.SCORES:
            value = metrics.get(name)
            results[key] = float(value) if isinstance(value, (int, float)) else None
        return results


class ExportLanelet2(CsboundaryAlgorithm):
    NAME = "exportlanelet2"
    TITLE = "Export Lanelet2"
    HELP = (
        "<p>The predicted boundaries as a Lanelet2 map (<code>csboundary export-lanelet2</code>): one road_border "
        "linestring per boundary, confidence as an attribute, Autoware's map_projector_info.yaml beside it.</p>"
    )

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(
            QgsProcessingParameterFile("PREDICTION", "Prediction folder", QgsProcessingParameterFile.Folder)
        )
        self.min_confidence_parameter()
        self.addParameter(QgsProcessingParameterFileDestination("OUTPUT", "Lanelet2 map", "OSM files (*.osm)"))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        prediction = self.prediction(parameters, context)
        out = self.parameterAsFileOutput(parameters, "OUTPUT", context)
        args = ["export-lanelet2", prediction, "--out", out]
        args += self.min_confidence_args(parameters, context)
        self.csboundary(args, feedback)
        return {"OUTPUT": out}


class ApplyReview(CsboundaryAlgorithm):
    NAME = "applyreview"
    TITLE = "Apply review"
    HELP = (
        "<p>Merges the review done in QGIS into the prediction (<code>csboundary apply-review</code>): the "
        "deleted, split, moved, reshaped and drawn boundaries of the review GeoPackage's <i>boundaries</i> layer and "
        "the polygons of its <i>complete</i> layer become the same edits as the review page's, checked the same way "
        "and recorded in review.json (the complete areas are labels for Fine-tune). Save your edits first. "
        "A fresh review GeoPackage of the corrected graph is written for the next round, and replaces the edited "
        "one's layers in the project.</p>"
    )

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(
            QgsProcessingParameterFile("PREDICTION", "Prediction folder", QgsProcessingParameterFile.Folder)
        )
        self.addParameter(QgsProcessingParameterFile("EDITED", "Edited review GeoPackage", extension="gpkg"))
        self.addParameter(
            QgsProcessingParameterFileDestination(
                "NEXT_REVIEW", "Review GeoPackage of the corrected graph", "GeoPackage (*.gpkg)"
            )
        )
        self.addOutput(QgsProcessingOutputVectorLayer("BOUNDARIES", "Road boundaries", QgsProcessing.TypeVectorLine))
        self.addOutput(QgsProcessingOutputFolder("PREDICTION", "Prediction folder"))

    def prepareAlgorithm(self, parameters, context, feedback):  # noqa: N802
        """On the main thread, where the project's layers may be read: which of them hold unsaved
        edits of the edited file (processAlgorithm refuses then, with the message in the log)."""
        edited = os.path.realpath(self.parameterAsFile(parameters, "EDITED", context))
        self.unsaved = [
            layer.name()
            for layer in QgsProject.instance().mapLayers().values()
            if isinstance(layer, QgsVectorLayer)
            and os.path.realpath(layer.source().split("|")[0]) == edited
            and layer.isEditable()
            and layer.isModified()
        ]
        return True

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        if getattr(self, "unsaved", None):
            raise QgsProcessingException(
                f"{', '.join(self.unsaved)} has unsaved edits: save them (Save Layer Edits) before Apply review"
            )
        prediction = self.prediction(parameters, context)
        edited = self.parameterAsFile(parameters, "EDITED", context)
        next_review = self.parameterAsFileOutput(parameters, "NEXT_REVIEW", context)
        if os.path.realpath(next_review) == os.path.realpath(edited):
            raise QgsProcessingException(
                f"{next_review}: the next review GeoPackage must be a new file, not the edited one"
            )
        self.csboundary(["apply-review", prediction, edited], feedback)
        self.csboundary(["review", prediction, "--gpkg", next_review, "--quiet"], feedback)
        results = {
            "PREDICTION": prediction,
            "NEXT_REVIEW": next_review,
            "BOUNDARIES": f"{os.path.join(prediction, 'boundaries.gpkg')}|layername={BOUNDARIES_LAYER}",
        }
        load(context, results["BOUNDARIES"], "road boundaries (reviewed)", "BOUNDARIES", "boundaries")
        load_review(context, next_review, "NEXT_REVIEW", "NEXT_REVIEW", "NEXT_REVIEW")
        self.edited = os.path.realpath(edited)
        return results

    def postProcessAlgorithm(self, context, feedback):  # noqa: N802 (on the main thread, where the project may change)
        """The edited file's layers leave the project: the next round's replace them."""
        edited = getattr(self, "edited", None)
        project = context.project()
        if edited and project is not None:
            stale = [
                layer.id()
                for layer in project.mapLayers().values()
                if isinstance(layer, QgsVectorLayer) and os.path.realpath(layer.source().split("|")[0]) == edited
            ]
            project.removeMapLayers(stale)
        return {}


class Finetune(CsboundaryAlgorithm):
    NAME = "finetune"
    TITLE = "Fine-tune on reviewed areas"
    HELP = (
        "<p>Fine-tunes the weights on the areas marked complete in reviewed predictions (<code>csboundary "
        "finetune</code>), with synthetic cities mixed in. Takes hours on a CPU; run again with the same work "
        "folder to continue a stopped run.</p>"
    )

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(
            QgsProcessingParameterFile("PREDICTION", "Reviewed prediction folder", QgsProcessingParameterFile.Folder)
        )
        self.training_parameters(1000, 500, "AfANet steps", 1, "Fine-tuned weights")

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.kept(self.parameterAsFileOutput(parameters, "OUTPUT", context), "The fine-tuned weights", feedback)
        self.csboundary(
            ["finetune", self.prediction(parameters, context), "--out", out, *self.training_args(parameters, context)],
            feedback,
        )
        return {"OUTPUT": out}


class Adapt(CsboundaryAlgorithm):
    NAME = "adapt"
    TITLE = "Adapt to your imagery (no labels)"
    HELP = (
        "<p>Adapts the weights to your city from its own unlabelled imagery (<code>csboundary adapt</code>): "
        "self-training of the FPN by an averaged teacher with synthetic cities mixed in, then AfANet. Measured "
        "gains and losses: docs/adapt.md. Run again with the same work folder to continue a stopped run.</p>"
    )

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(
            QgsProcessingParameterMultipleLayers("INPUT", "Aerial imagery (GeoTIFF)", QgsProcessing.TypeRaster)
        )
        self.addParameter(QgsProcessingParameterBoolean("MIX", "Paste synthetic roadway into your windows", True))
        self.training_parameters(800, 300, "AfANet steps (0: keep the bundle's)", 0, "Adapted weights")

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        out = self.kept(self.parameterAsFileOutput(parameters, "OUTPUT", context), "The adapted weights", feedback)
        mix = self.parameterAsBoolean(parameters, "MIX", context)
        self.csboundary(
            [
                "adapt",
                *imagery_files(self, parameters, "INPUT", context),
                "--out",
                out,
                "--mix" if mix else "--no-mix",
                *self.training_args(parameters, context),
            ],
            feedback,
        )
        return {"OUTPUT": out}


ALGORITHMS = (Detect, Evaluate, ExportLanelet2, ApplyReview, Finetune, Adapt)
