"""What a scene is made of, as :mod:`.render` paints it: painted ground polygons, buildings,
trees and cars, and the :class:`Scene` that holds them with the city's sun and look.

Plain data, so the modules that place things (:mod:`.blocks`, :mod:`.buildings`, ...) share it
without importing one another.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from shapely.geometry import Polygon

from csboundary.data.synth.materials import ASPHALT, Colour
from csboundary.data.synth.streets import StreetNetwork


@dataclass
class Painted:
    """A ground-level polygon with a colour and a texture roughness."""

    polygon: Polygon
    colour: Colour
    roughness: int


@dataclass
class Building:
    footprint: Polygon
    height: float
    roof: Colour
    detail: Polygon | None = None  # a roof structure of another shade
    detail_colour: Colour = (0, 0, 0, 0)
    facets: list[tuple[Polygon, float]] = field(default_factory=list)  # pitched roof: facet, brightness factor
    ridge: Polygon | None = None  # pitched roof: the ridge line as a thin strip
    parapet: Colour | None = None  # flat roof: a rim of this colour, ``parapet_width`` wide, along the outline
    parapet_width: float = 0.0
    roof_items: list[tuple[Polygon, Colour]] = field(default_factory=list)  # units, tanks, wells and their shadows


@dataclass
class Tree:
    x: float
    y: float
    radius: float
    colour: Colour
    shape_seed: int = 0
    lobes: int = 5  # crown lobes (render: 5 = simple crown, more = lobes lit from the sun's side)
    bare: bool = False  # leafless: branches over a see-through crown (``bare_tree_share``)


@dataclass
class Car:
    body: Polygon
    colour: Colour
    cabin: Polygon
    detail: bool = False  # drawn with windows, a lit roof and a shadow (``car_detail``)


@dataclass
class Scene:
    network: StreetNetwork
    ground: list[Painted] = field(default_factory=list)  # in drawing order, after the asphalt base
    markings: list[Painted] = field(default_factory=list)  # painted before blocks, so curbs clip them
    cars: list[Car] = field(default_factory=list)
    buildings: list[Building] = field(default_factory=list)
    trees: list[Tree] = field(default_factory=list)
    sun: tuple[float, float] = (0.5, -0.3)  # shadow offset per metre of height (x, y)
    road: Colour = ASPHALT  # the roadway's material, painted under everything
    lean: tuple[float, float] = (0.0, 0.0)  # relief displacement of roofs, metres per metre of height (x, y)
    texture: float = 0.0  # ``photo_texture``: amplitude of the texture at every scale
