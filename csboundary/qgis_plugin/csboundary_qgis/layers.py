"""What the algorithms load into the project when they end: the layers of a prediction's and a
review's GeoPackages, by name, styled (styles.py) as what they are."""

from qgis.core import QgsProcessingContext, QgsProcessingUtils

from .styles import Styler

BOUNDARIES_LAYER = "road_boundaries"  # in the prediction's boundaries.gpkg
DRAFT_LAYER = "boundaries"  # the review draft's boundaries, in the review GeoPackage
HELD_BACK_LAYER = "held_back"  # the boundaries not worth a look, in the review GeoPackage (loaded hidden)
COMPLETE_LAYER = "complete"  # polygons a reviewer marks checked, in the review GeoPackage
REVIEW_GPKG = "review.gpkg"  # the boundaries that a reviewer edits, beside the prediction


def load(context, source, name, output, kind):
    """Have Processing load ``source`` into the project when the algorithm ends, styled as ``kind``."""
    if context.project() is None:
        return
    details = QgsProcessingContext.LayerDetails(name, context.project(), output, QgsProcessingUtils.LayerHint.Vector)
    details.forceName = (
        True  # our name, not the GeoPackage layer's ("Prefer output filename for layer names" is on by default)
    )
    details.setPostProcessor(Styler.make(kind))
    context.addLayerToLoadOnCompletion(source, details)


def load_review(context, review, boundaries_output, held_output, complete_output):
    """The review GeoPackage's three layers: the draft's boundaries, those held back (hidden) and the areas checked."""
    load(context, f"{review}|layername={DRAFT_LAYER}", "boundaries to review", boundaries_output, "review")
    load(context, f"{review}|layername={HELD_BACK_LAYER}", "held back from the review", held_output, "held")
    load(context, f"{review}|layername={COMPLETE_LAYER}", "areas checked", complete_output, "complete")
