"""Exact WGS-84 conversions: geodetic <-> ECEF <-> local NED/ENU.

Everything a scenario places (vehicles, later targets and ground imagery)
lives in one local tangent frame anchored at the scenario origin. This
module owns that frame and nothing else; it never touches JSBSim.

Heights are ellipsoidal (above the WGS-84 ellipsoid), which is what JSBSim
calls "sea level": cosim has no geoid model, so ``alt_msl_m`` means height
above the ellipsoid throughout. All functions accept scalars or numpy
arrays and broadcast.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_EP2 = WGS84_E2 / (1.0 - WGS84_E2)

#: the farthest a scenario places anything (vehicles, targets, commanded
#: points) from its origin, horizontally (m). The frame is exact at any
#: distance; a scenario spanning more is almost surely a unit mistake.
MAX_DISTANCE_M = 1_000_000.0

Array = NDArray[np.float64]


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike
                     ) -> tuple[Array, Array, Array]:
    """WGS-84 geodetic latitude, longitude (degrees) and height (m) to ECEF (m)."""
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    h = np.asarray(h_m, dtype=np.float64)
    sin_lat = np.sin(lat)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat * sin_lat)
    x = (n + h) * np.cos(lat) * np.cos(lon)
    y = (n + h) * np.cos(lat) * np.sin(lon)
    z = (n * (1.0 - WGS84_E2) + h) * sin_lat
    return x, y, z


def ecef_to_geodetic(x_m: ArrayLike, y_m: ArrayLike, z_m: ArrayLike
                     ) -> tuple[Array, Array, Array]:
    """ECEF (m) to WGS-84 geodetic latitude, longitude (degrees) and height (m).

    Bowring's parametric start followed by Newton refinement of the latitude;
    converges to well below a micrometre for any point above the Earth's
    centre region (|height| < 1000 km is the tested range).
    """
    x = np.asarray(x_m, dtype=np.float64)
    y = np.asarray(y_m, dtype=np.float64)
    z = np.asarray(z_m, dtype=np.float64)
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    # Bowring (1976) initial estimate.
    beta = np.arctan2(z * WGS84_A_M, p * WGS84_B_M)
    lat = np.arctan2(z + WGS84_EP2 * WGS84_B_M * np.sin(beta) ** 3,
                     p - WGS84_E2 * WGS84_A_M * np.cos(beta) ** 3)
    for _ in range(3):
        sin_lat = np.sin(lat)
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat * sin_lat)
        lat = np.arctan2(z + n * WGS84_E2 * sin_lat, p)
    sin_lat = np.sin(lat)
    cos_lat = np.cos(lat)
    # Height: project onto the normal (stable at all latitudes).
    h = p * cos_lat + z * sin_lat - WGS84_A_M * np.sqrt(1.0 - WGS84_E2 * sin_lat * sin_lat)
    return np.degrees(lat), np.degrees(lon), h


@dataclass(frozen=True)
class LocalFrame:
    """A local tangent frame (NED and ENU) anchored at a geodetic origin."""

    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0

    def _rotation(self) -> tuple[float, float, float, float]:
        """sin and cos of the origin's latitude and longitude: the rows of the
        rotation ECEF -> NED are (-sl*co, -sl*so, cl), (-so, co, 0) and
        (-cl*co, -cl*so, -sl)."""
        lat = np.radians(self.lat_deg)
        lon = np.radians(self.lon_deg)
        return float(np.sin(lat)), float(np.cos(lat)), float(np.sin(lon)), float(np.cos(lon))

    def _origin_ecef(self) -> Array:
        return np.array(geodetic_to_ecef(self.lat_deg, self.lon_deg, self.alt_m))

    # The rotations are written out element by element (no matrix product):
    # BLAS picks different summation orders for different array sizes, and
    # each point's result must not depend on how many are converted at once.

    def geodetic_to_ned(self, lat_deg: ArrayLike, lon_deg: ArrayLike, alt_m: ArrayLike
                        ) -> tuple[Array, Array, Array]:
        """Geodetic position(s) to north, east, down metres from the origin."""
        x, y, z = geodetic_to_ecef(lat_deg, lon_deg, alt_m)
        o = self._origin_ecef()
        dx, dy, dz = np.broadcast_arrays(x - o[0], y - o[1], z - o[2])
        sl, cl, so, co = self._rotation()
        north = (-sl * co) * dx + (-sl * so) * dy + cl * dz
        east = -so * dx + co * dy
        down = (-cl * co) * dx + (-cl * so) * dy - sl * dz
        return north, east, down

    def ned_to_geodetic(self, north_m: ArrayLike, east_m: ArrayLike, down_m: ArrayLike
                        ) -> tuple[Array, Array, Array]:
        """North, east, down metres from the origin to geodetic lat, lon (deg), height (m)."""
        n, e, d = np.broadcast_arrays(np.asarray(north_m, dtype=np.float64),
                                      np.asarray(east_m, dtype=np.float64),
                                      np.asarray(down_m, dtype=np.float64))
        sl, cl, so, co = self._rotation()
        dx = (-sl * co) * n - so * e + (-cl * co) * d
        dy = (-sl * so) * n + co * e + (-cl * so) * d
        dz = cl * n - sl * d
        o = self._origin_ecef()
        return ecef_to_geodetic(dx + o[0], dy + o[1], dz + o[2])

    def place(self, north_m: ArrayLike, east_m: ArrayLike, height_m: ArrayLike
              ) -> tuple[Array, Array]:
        """Latitude and longitude (deg) of the point at ``height_m`` above the
        ellipsoid whose local north/east coordinates are exactly ``north_m``,
        ``east_m`` (solves for the matching ``down``; exact to well below 1 um)."""
        n = np.asarray(north_m, dtype=np.float64)
        e = np.asarray(east_m, dtype=np.float64)
        h = np.asarray(height_m, dtype=np.float64)
        d = -(h - self.alt_m) + 0.0 * n  # flat-earth first guess, broadcast
        for _ in range(4):
            lat, lon, hh = self.ned_to_geodetic(n, e, d)
            d = d + (hh - h)  # moving down by x lowers the height by ~x (cos < 1e-3 off)
        lat, lon, _ = self.ned_to_geodetic(n, e, d)
        return lat, lon


def bearing_deg(lat1_deg: ArrayLike, lon1_deg: ArrayLike, h1_m: ArrayLike,
                lat2_deg: ArrayLike, lon2_deg: ArrayLike, h2_m: ArrayLike) -> Array:
    """True bearing (deg, 0..360) from point 1 to point 2, measured in point 1's
    own local tangent frame (exact; no flat-earth or origin-north shortcut)."""
    x1, y1, z1 = geodetic_to_ecef(lat1_deg, lon1_deg, h1_m)
    x2, y2, z2 = geodetic_to_ecef(lat2_deg, lon2_deg, h2_m)
    dx, dy, dz = x2 - x1, y2 - y1, z2 - z1
    lat = np.radians(np.asarray(lat1_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon1_deg, dtype=np.float64))
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    north = -sl * co * dx - sl * so * dy + cl * dz
    east = -so * dx + co * dy
    return np.degrees(np.arctan2(east, north)) % 360.0
