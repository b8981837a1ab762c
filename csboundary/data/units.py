"""True metres from any coordinate system: projected (metres, US feet, ...), geographic
(degrees) or none at all (pixels of a stated size).

Every length and area the project reports (``length_m``, ``boundary_km``, ``area_km2``) goes
through :class:`GroundUnits`, so EPSG:4326 input is not measured in degrees and EPSG:2263 input
not in feet labelled as metres. Geographic lengths are geodesic on the CRS's ellipsoid; projected
ones are the CRS's own lengths times its unit's size in metres (a projection's scale error, under
0.1 % for UTM and state planes, is not corrected).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MODEL_GSD = 0.152  # metres per pixel the shipped model was trained at (the NYC benchmark's 0.5 ft)


@dataclass(frozen=True)
class GroundUnits:
    """How coordinates of one CRS (or of a CRS-less pixel grid) relate to metres near a place.

    ``metres_per_unit`` is (east, north) metres per coordinate unit at the place (for a
    geographic CRS, per degree of longitude and of latitude there); ``geod`` is set for geographic
    CRSs, whose lengths are then measured on the ellipsoid.
    """

    metres_per_unit: tuple[float, float]
    unit_name: str
    geod: object | None = None

    @property
    def geographic(self) -> bool:
        return self.geod is not None

    def line_length_m(self, coords: np.ndarray) -> float:
        """Length in metres of a polyline given in this CRS's coordinates, (N, 2)."""
        coords = np.asarray(coords, dtype=float)
        if len(coords) < 2:
            return 0.0
        if self.geod is not None:
            return float(self.geod.line_length(coords[:, 0], coords[:, 1]))
        d = np.diff(coords, axis=0) * np.asarray(self.metres_per_unit)
        return float(np.linalg.norm(d, axis=1).sum())

    def area_km2(self, bounds: tuple[float, float, float, float]) -> float:
        """Area in km2 of the rectangle (minx, miny, maxx, maxy) in this CRS's coordinates."""
        minx, miny, maxx, maxy = bounds
        if self.geod is not None:
            area, _ = self.geod.polygon_area_perimeter([minx, maxx, maxx, minx], [miny, miny, maxy, maxy])
            return abs(float(area)) / 1e6
        return (maxx - minx) * self.metres_per_unit[0] * (maxy - miny) * self.metres_per_unit[1] / 1e6


def ground_units(crs, at: tuple[float, float] | None = None, pixel_metres: float | None = None) -> GroundUnits | None:
    """The :class:`GroundUnits` of ``crs`` near the point ``at`` (its coordinates), or of a
    CRS-less grid whose unit is a pixel of ``pixel_metres``; None when neither is known."""
    if crs is None:
        return GroundUnits((pixel_metres, pixel_metres), "pixel") if pixel_metres else None
    from pyproj import CRS

    crs = CRS.from_user_input(crs)
    if crs.is_geographic:
        geod = crs.get_geod()
        lon, lat = at if at is not None else (0.0, 0.0)
        lat = min(max(lat, -89.9), 89.9)
        step = 1e-4
        east = geod.inv(lon, lat, lon + step, lat)[2] / step
        north = geod.inv(lon, lat - step / 2, lon, lat + step / 2)[2] / step
        return GroundUnits((east, north), "degree", geod)
    axis = crs.axis_info[0] if crs.axis_info else None
    factor = axis.unit_conversion_factor if axis is not None and axis.unit_conversion_factor else 1.0
    name = axis.unit_name if axis is not None else "metre"
    return GroundUnits((factor, factor), name)


def pixel_size_m(units: GroundUnits, transform) -> tuple[float, float]:
    """(east, north) metres per pixel of a north-up ``transform`` in ``units``' coordinates."""
    return abs(transform.a) * units.metres_per_unit[0], abs(transform.e) * units.metres_per_unit[1]


def geometric_mean(values: tuple[float, float]) -> float:
    return math.sqrt(values[0] * values[1])
