"""Drives the plugin inside QGIS (headless), for tests/qgis_plugin/test_in_qgis.py: run by QGIS's
own Python (Debian's python3-qgis), never by the test suite's. Usage:

    python3 qgis_session.py PLUGIN_DIR REQUEST.json REPORT.json

The request's "mode" says what to do: "detect" (run Detect as the Processing dialog does, report
the layers loaded into the project, render a picture of them), "review" (edit the review
GeoPackage with QGIS's editing API, run Apply review), "cancel" (cancel Detect once a patch is
done, then run it again into the same folder). The report is JSON, for the test to check.
"""

import json
import os
import sys
import time

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from qgis.core import (  # noqa: E402
    QgsApplication,
    QgsExpressionContextUtils,
    QgsFeature,
    QgsGeometry,
    QgsMapRendererSequentialJob,
    QgsMapSettings,
    QgsPointXY,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProject,
    QgsRasterLayer,
    QgsRectangle,
    QgsRenderContext,
    QgsVectorLayer,
)
from qgis.PyQt.QtCore import QSize  # noqa: E402
from qgis.PyQt.QtGui import QColor  # noqa: E402

PLUGIN_DIR, REQUEST, REPORT = sys.argv[1:4]
sys.path.insert(0, "/usr/share/qgis/python/plugins")
sys.path.insert(0, PLUGIN_DIR)

app = QgsApplication([], False)
app.initQgis()
from processing.core.Processing import Processing  # noqa: E402

Processing.initialize()
import processing  # noqa: E402
from csboundary_qgis.provider import CsboundaryProvider  # noqa: E402

provider = CsboundaryProvider()
QgsApplication.processingRegistry().addProvider(provider)
with open(REQUEST) as _file:
    request = json.load(_file)


class Feedback(QgsProcessingFeedback):
    """Keeps what the algorithm says; cancels once the named stage has passed ``cancel_after`` percent."""

    def __init__(self, cancel_stage=None, cancel_after=None):
        super().__init__()
        self.stages, self.percents, self.lines, self.errors = [], [], [], []
        self.cancel_stage, self.cancel_after, self.canceled_at = cancel_stage, cancel_after, None

    def setProgressText(self, text):  # noqa: N802
        self.stages.append(text)
        super().setProgressText(text)

    def setProgress(self, value):  # noqa: N802
        self.percents.append(value)
        super().setProgress(value)
        if (
            self.cancel_after is not None
            and self.canceled_at is None
            and self.stages[-1:] == [self.cancel_stage]
            and value > self.cancel_after
        ):
            self.canceled_at = time.monotonic()
            self.cancel()

    def reportError(self, error, fatalError=False):  # noqa: N802, N803 (QGIS's names)
        self.errors.append(error)
        super().reportError(error, fatalError)

    def pushConsoleInfo(self, text):  # noqa: N802
        self.lines.append(text)
        super().pushConsoleInfo(text)


def layer_report(layer):
    renderer = layer.renderer()
    node = QgsProject.instance().layerTreeRoot().findLayer(layer.id())
    report = {
        "name": layer.name(),
        "source": layer.source(),
        "type": layer.type(),
        "features": None,
        "renderer": None,
        "visible": node.isVisible() if node is not None else None,
    }
    if isinstance(layer, QgsVectorLayer):
        report.update(
            features=layer.featureCount(),
            geometry_type=layer.geometryType(),
            crs=layer.crs().authid(),
            fields=[f.name() for f in layer.fields()],
            renderer=renderer.type(),
        )
        if renderer.type() == "graduatedSymbol":
            report["class_attribute"] = renderer.classAttribute()
            drawn = QgsFeature(layer.fields())  # a line a reviewer drew: every attribute NULL
            drawn.setGeometry(QgsGeometry.fromPolylineXY([QgsPointXY(0, 0), QgsPointXY(1, 1)]))
            context = QgsRenderContext()  # as the map canvas prepares it: the layer's scopes, then the feature
            context.expressionContext().appendScopes(QgsExpressionContextUtils.globalProjectLayerScopes(layer))
            renderer.startRender(context, layer.fields())
            context.expressionContext().setFeature(drawn)
            symbol = renderer.symbolForFeature(drawn, context)
            report["null_colour"] = symbol.color().name() if symbol is not None else None
            renderer.stopRender(context)
            report["classes"] = [
                {
                    "lower": r.lowerValue(),
                    "upper": r.upperValue(),
                    "colour": r.symbol().color().name(),
                    "label": r.label(),
                }
                for r in renderer.ranges()
            ]
    return report


def render(path, layers, extent, crs, size=1200):
    settings = QgsMapSettings()
    settings.setLayers(layers)
    settings.setDestinationCrs(crs)
    settings.setExtent(extent)
    settings.setOutputSize(QSize(size, size))
    settings.setBackgroundColor(QColor("white"))
    job = QgsMapRendererSequentialJob(settings)
    job.start()
    job.waitForFinished()
    job.renderedImage().save(path, "JPG", 85)


def detect():
    feedback = Feedback()
    results = processing.runAndLoadResults("csboundary:detect", request["parameters"], feedback=feedback)
    layers = list(QgsProject.instance().mapLayers().values())
    report = {
        "results": {k: str(v) for k, v in results.items()},
        "layers": [layer_report(layer) for layer in layers],
        "stages": feedback.stages,
        "percents": feedback.percents[-3:],
        "lines": feedback.lines,
    }
    if request.get("picture"):
        tiles = [QgsRasterLayer(path, os.path.basename(path)) for path in request["parameters"]["INPUT"]]
        by_name = {layer.name(): layer for layer in layers}
        shown = [by_name["areas checked"], by_name["boundaries to review"]] + tiles
        extent = QgsRectangle()
        for tile in tiles:
            extent.combineExtentWith(tile.extent())
        x, y, half = extent.center().x(), extent.center().y(), extent.width() * request.get("zoom", 0.5) / 2
        render(request["picture"], shown, QgsRectangle(x - half, y - half, x + half, y + half), tiles[0].crs())
        report["picture"] = request["picture"]
    return report


def review():
    """Edit as a person does in QGIS: delete a boundary, drag a boundary end (every boundary ending
    at that vertex follows, as topological editing does), draw a line, draw a polygon; save; Apply
    review."""
    edited = request["edited"]
    refusals = {}
    for name, parameters in (
        ("same_file", {"PREDICTION": request["prediction"], "EDITED": edited, "NEXT_REVIEW": edited}),
        ("unsaved", {"PREDICTION": request["prediction"], "EDITED": edited, "NEXT_REVIEW": request["next_review"]}),
    ):
        open_layer = QgsVectorLayer(f"{edited}|layername=boundaries", "boundaries to review", "ogr")
        QgsProject.instance().addMapLayer(open_layer)
        if name == "unsaved":  # a deletion not saved yet
            open_layer.startEditing()
            open_layer.deleteFeature(next(open_layer.getFeatures()).id())
        said = Feedback()
        try:
            processing.run("csboundary:applyreview", parameters, feedback=said)
            refusals[name] = "accepted"
        except (
            QgsProcessingException
        ) as exc:  # what the Processing dialog's log shows: the feedback's errors, else the exception
            refusals[name] = said.errors[-1] if said.errors else str(exc)
        if open_layer.isEditable():
            open_layer.rollBack()
        QgsProject.instance().removeMapLayer(open_layer.id())
    edges = QgsVectorLayer(f"{edited}|layername=boundaries", "boundaries", "ogr")
    complete = QgsVectorLayer(f"{edited}|layername=complete", "complete", "ogr")
    assert edges.isValid() and complete.isValid()
    edges.startEditing()
    gone = next(f for f in edges.getFeatures() if request["delete_edge"] in [int(k) for k in f["edge_ids"].split(";")])
    edges.deleteFeature(gone.id())
    (fx, fy), (x, y) = request["move_from"], request["move_to"]
    moved = 0
    for feature in edges.getFeatures():
        line = feature.geometry().asPolyline()
        for index in sorted({0, len(line) - 1}):
            if abs(line[index].x() - fx) < 1e-6 and abs(line[index].y() - fy) < 1e-6:
                edges.moveVertex(x, y, feature.id(), index)
                moved += 1
    drawn = QgsFeature(edges.fields())
    drawn.setGeometry(QgsGeometry.fromPolylineXY([QgsPointXY(px, py) for px, py in request["draw"]]))
    edges.addFeature(drawn)
    assert edges.commitChanges(), edges.commitErrors()
    complete.startEditing()
    area = QgsFeature(complete.fields())
    area.setGeometry(QgsGeometry.fromPolygonXY([[QgsPointXY(px, py) for px, py in request["area"]]]))
    complete.addFeature(area)
    assert complete.commitChanges(), complete.commitErrors()
    del edges, complete  # close the GeoPackage before csboundary reads it
    shown = QgsVectorLayer(
        f"{edited}|layername=boundaries", "boundaries to review", "ogr"
    )  # as Detect left it in the project
    QgsProject.instance().addMapLayer(shown)
    feedback = Feedback()
    results = processing.runAndLoadResults(
        "csboundary:applyreview",
        {"PREDICTION": request["prediction"], "EDITED": edited, "NEXT_REVIEW": request["next_review"]},
        feedback=feedback,
    )
    sources = [layer.source() for layer in QgsProject.instance().mapLayers().values()]
    return {
        "results": {k: str(v) for k, v in results.items()},
        "line_ends_moved": moved,
        "lines": feedback.lines,
        "refusals": refusals,
        "sources_after": sources,
    }


def cancel():
    feedback = Feedback(cancel_stage="predict patches", cancel_after=0)
    started = time.monotonic()
    try:
        processing.run("csboundary:detect", request["parameters"], feedback=feedback)
        outcome = "finished"
    except QgsProcessingException as exc:
        outcome = str(exc)
    stopped = time.monotonic()
    report = {
        "outcome": outcome,
        "seconds_to_cancel": feedback.canceled_at and stopped - feedback.canceled_at,
        "seconds_before_cancel": feedback.canceled_at and feedback.canceled_at - started,
        "lines": feedback.lines,
    }
    again = Feedback()
    processing.run("csboundary:detect", request["parameters"], feedback=again)
    report["again_lines"] = again.lines
    return report


def missing_command():
    os.environ["CSBOUNDARY_COMMAND"] = request["command"]
    try:
        processing.run("csboundary:detect", request["parameters"], feedback=Feedback())
        return {"outcome": "finished"}
    except QgsProcessingException as exc:
        return {"outcome": str(exc)}


MODES = {"detect": detect, "review": review, "cancel": cancel, "missing_command": missing_command}
report = MODES[request["mode"]]()
QgsProject.instance().clear()
with open(REPORT, "w") as file:
    json.dump(report, file, indent=1)
app.exitQgis()
