"""How the loaded layers look: boundaries graduated by confidence (held-back ones hidden), the least sure in a
warm colour (the order in which a reviewer looks at them), checked areas as green outlines."""

from qgis.core import (
    QgsFillSymbol,
    QgsGraduatedSymbolRenderer,
    QgsLineSymbol,
    QgsProcessingLayerPostProcessorInterface,
    QgsProject,
    QgsRendererRange,
    QgsSingleSymbolRenderer,
)

# (lower, upper, colour, label): the classes of the calibrated probability that an edge is a true
# boundary; a line a reviewer drew has no confidence (NULL, classed as -1) and is drawn grey
CONFIDENCE_CLASSES = (
    (-1.5, -0.5, "#707070", "drawn (no confidence)"),
    (0.0, 0.25, "#d7301f", "least sure (< 0.25)"),
    (0.25, 0.5, "#fc8d59", "0.25 - 0.5"),
    (0.5, 0.75, "#91bfdb", "0.5 - 0.75"),
    (0.75, 1.0001, "#2166ac", "sure (>= 0.75)"),
)


def confidence_renderer(field: str, width: float = 0.8) -> QgsGraduatedSymbolRenderer:
    ranges = []
    for lower, upper, colour, label in CONFIDENCE_CLASSES:
        symbol = QgsLineSymbol.createSimple({"line_color": colour, "line_width": str(width), "capstyle": "round"})
        ranges.append(QgsRendererRange(lower, upper, symbol, label))
    return QgsGraduatedSymbolRenderer(f'coalesce("{field}", -1)', ranges)


def complete_renderer() -> QgsSingleSymbolRenderer:
    symbol = QgsFillSymbol.createSimple(
        {"color": "0,0,0,0", "outline_color": "#1a9850", "outline_width": "0.6", "outline_style": "dash"}
    )
    return QgsSingleSymbolRenderer(symbol)


class Styler(QgsProcessingLayerPostProcessorInterface):
    """Styles a layer once Processing has loaded it into the project. Processing keeps only a
    pointer to a post-processor, so every one made is kept here for the session."""

    kept = []

    def __init__(self, kind: str):
        super().__init__()
        self.kind = kind

    @classmethod
    def make(cls, kind: str) -> "Styler":
        styler = cls(kind)
        cls.kept.append(styler)
        return styler

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802 (QGIS's name; runs on the main thread)
        if self.kind in ("review", "held"):
            layer.setRenderer(confidence_renderer("confidence", width=1.0))
        elif self.kind == "boundaries":
            layer.setRenderer(confidence_renderer("confidence_mean", width=1.0))
        elif self.kind == "complete":
            layer.setRenderer(complete_renderer())
        if self.kind == "held":  # not worth a look: off until the reviewer asks for it
            node = (context.project() or QgsProject.instance()).layerTreeRoot().findLayer(layer.id())
            if node is not None:
                node.setItemVisibilityChecked(False)
        layer.triggerRepaint()
