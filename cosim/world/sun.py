"""The sun: where it stands in the sky of a scenario (the ``sun:`` section).

Either from a date and time at the scenario's origin (``time``: ISO 8601 with
its UTC offset, e.g. ``2026-06-21T14:30:00+02:00``) or given directly
(``azimuth_deg``, clockwise from true north, and ``elevation_deg`` above the
horizon); ``shadows`` (default true) lets the targets cast shadows on the
ground. Without the section the sun stands where cosim has always put it,
50 deg up in the south-east, and casts no shadow (``DEFAULT``).

The position is geometric (no refraction, which lifts the sun by less than
0.1 deg above 10 deg of elevation), from the low-precision solar coordinates
of Meeus (*Astronomical Algorithms*, 2nd ed., ch. 25, as in NOAA's solar
calculator): the sun's apparent longitude and the obliquity give its
declination, the equation of time and the longitude the hour angle. It
agrees with NREL's solar position algorithm (Reda and Andreas 2004) to about
0.01 deg over 1950-2050 (docs/physics.md). cosim draws daylight: a time when
the sun is below 1 deg of elevation at the origin is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

import numpy as np

from cosim.core.section import SectionContext

P = tuple[Any, ...]

#: the lowest sun cosim draws (deg): a lower one would light the ground from
#: below the terrain it does not model, and its shadows would be kilometres long
MIN_ELEVATION_DEG = 1.0
#: the years a ``time`` may fall in (the solar coordinates' accuracy holds there)
YEARS = (1900, 2100)


@dataclass(frozen=True)
class SunSpec:
    azimuth_deg: float  # clockwise from true north
    elevation_deg: float  # above the horizon
    time: str = ""  # the ISO time it was computed from, if any
    shadows: bool = False  # targets cast shadows on the ground

    def to_sun_ned(self) -> np.ndarray:
        """The unit vector toward the sun in north-east-down axes."""
        el, az = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                         -math.sin(el)])


#: the sun without a ``sun:`` section: 50 deg up, from the south-east
DEFAULT = SunSpec(azimuth_deg=135.0, elevation_deg=50.0)


def _julian_day(when: datetime) -> float:
    """Julian day of an aware datetime (UTC), with its fraction."""
    t = when.astimezone(timezone.utc)
    unix_s = (t - datetime(1970, 1, 1, tzinfo=timezone.utc)).total_seconds()
    return unix_s / 86400.0 + 2440587.5


def solar_position(when: datetime, lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """(azimuth_deg clockwise from north in [0, 360), elevation_deg) of the
    sun's centre at ``when`` (timezone-aware) seen from (lat, lon), without
    refraction."""
    if when.tzinfo is None:
        raise ValueError("solar_position needs a time with its UTC offset")
    jd = _julian_day(when)
    t = (jd - 2451545.0) / 36525.0  # Julian centuries since J2000.0
    l0 = math.radians((280.46646 + t * (36000.76983 + 0.0003032 * t)) % 360.0)
    m = math.radians(357.52911 + t * (35999.05029 - 0.0001537 * t))
    e = 0.016708634 - t * (0.000042037 + 0.0000001267 * t)
    c = (math.sin(m) * (1.914602 - t * (0.004817 + 0.000014 * t))
         + math.sin(2 * m) * (0.019993 - 0.000101 * t) + math.sin(3 * m) * 0.000289)
    omega = math.radians(125.04 - 1934.136 * t)
    app_long = math.radians(math.degrees(l0) + c - 0.00569 - 0.00478 * math.sin(omega))
    eps0 = 23.0 + (26.0 + (21.448 - t * (46.815 + t * (0.00059 - t * 0.001813))) / 60.0) / 60.0
    eps = math.radians(eps0 + 0.00256 * math.cos(omega))
    decl = math.asin(math.sin(eps) * math.sin(app_long))
    y = math.tan(eps / 2) ** 2
    eot_min = 4.0 * math.degrees(
        y * math.sin(2 * l0) - 2 * e * math.sin(m) + 4 * e * y * math.sin(m) * math.cos(2 * l0)
        - 0.5 * y * y * math.sin(4 * l0) - 1.25 * e * e * math.sin(2 * m))
    utc = when.astimezone(timezone.utc)
    minutes = utc.hour * 60.0 + utc.minute + (utc.second + utc.microsecond * 1e-6) / 60.0
    hour_angle = math.radians((minutes + eot_min + 4.0 * lon_deg) / 4.0 - 180.0)
    lat = math.radians(lat_deg)
    sin_el = (math.sin(lat) * math.sin(decl)
              + math.cos(lat) * math.cos(decl) * math.cos(hour_angle))
    el = math.asin(max(-1.0, min(1.0, sin_el)))
    az = math.atan2(math.sin(hour_angle),
                    math.cos(hour_angle) * math.sin(lat) - math.tan(decl) * math.cos(lat))
    return (math.degrees(az) + 180.0) % 360.0, math.degrees(el)


def parse_sun(info: SectionContext, node: Any, path: P) -> SunSpec:
    """The ``sun:`` section: ``{time: ISO}`` or ``{azimuth_deg, elevation_deg}``."""
    r = info.reader(node, path, ("time", "azimuth_deg", "elevation_deg", "shadows"))
    shadows = r.boolean("shadows", True)
    if r.has("time"):
        if r.has("azimuth_deg") or r.has("elevation_deg"):
            info.err(path, "give time, or azimuth_deg and elevation_deg, not both")
            return DEFAULT
        text = r.string("time")
        if text is None:
            return DEFAULT
        try:
            when = datetime.fromisoformat(text)
        except ValueError:
            info.err(path + ("time",), f"{text!r} is not an ISO 8601 time (expected e.g. "
                                       "2026-06-21T14:30:00+02:00)")
            return DEFAULT
        if when.tzinfo is None:
            info.err(path + ("time",), f"{text!r} has no UTC offset (add one: +00:00, Z, "
                                       "+02:00, ...)")
            return DEFAULT
        if not YEARS[0] <= when.astimezone(timezone.utc).year < YEARS[1]:
            info.err(path + ("time",), f"{text!r}: the year must be in {YEARS[0]}..{YEARS[1] - 1}")
            return DEFAULT
        az, el = solar_position(when, info.origin.lat_deg, info.origin.lon_deg)
        if el < MIN_ELEVATION_DEG:
            info.err(path + ("time",), f"at {text} the sun is {el:.1f} deg above the horizon at "
                                       f"the origin; cosim draws daylight (at least "
                                       f"{MIN_ELEVATION_DEG:g} deg)")
            return DEFAULT
        return SunSpec(round(az, 6), round(el, 6), text, shadows)
    if not (r.has("azimuth_deg") and r.has("elevation_deg")):
        info.err(path, "expected time, or azimuth_deg and elevation_deg")
        return DEFAULT
    az = r.num("azimuth_deg", lo=0.0, hi=360.0)
    el = r.num("elevation_deg", lo=MIN_ELEVATION_DEG, hi=90.0)
    if az is None or el is None:
        return DEFAULT
    return SunSpec(float(az), float(el), "", shadows)
