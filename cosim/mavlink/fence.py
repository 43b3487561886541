"""A vehicle's geofence as ArduPilot's fence list gives it: inclusion and
exclusion polygons (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_*: consecutive vertices,
param1 the vertex count) and circles (MAV_CMD_NAV_FENCE_CIRCLE_*: param1 the
radius in metres). A vehicle is outside its fence when it is outside any
inclusion zone or inside any exclusion zone (ArduPilot's rule); the return
point item is kept for downloads only (a breach returns to home or the
nearest rally point, as ArduPilot's RTL action does).

Distances use a flat-earth approximation round the zone's first vertex or
centre (well under 1 m over a few kilometres)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from cosim.mavlink import adapter as mav
from cosim.mavlink.mission import MissionItem, flat_ne

_INCL_POLY = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
_EXCL_POLY = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
_INCL_CIRCLE = mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
_EXCL_CIRCLE = mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION


def _inside_polygon(vertices: Sequence[MissionItem], lat: float, lon: float) -> bool:
    """Even-odd rule, in metres round the first vertex."""
    lat0, lon0 = vertices[0].lat_deg, vertices[0].lon_deg
    pts = [flat_ne(lat0, lon0, v.lat_deg, v.lon_deg) for v in vertices]
    y, x = flat_ne(lat0, lon0, lat, lon)
    inside = False
    for (y1, x1), (y2, x2) in zip(pts, pts[1:] + pts[:1]):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def zones(items: Sequence[MissionItem]) -> list[tuple[bool, str, list[MissionItem]]]:
    """(inclusion, "polygon" | "circle", items) for each zone of a fence list;
    a polygon whose vertex count disagrees with the list is left out."""
    out: list[tuple[bool, str, list[MissionItem]]] = []
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in (_INCL_POLY, _EXCL_POLY):
            n = int(it.param1)
            group = list(items[i:i + n])
            if n >= 3 and len(group) == n and all(g.command == it.command for g in group):
                out.append((it.command == _INCL_POLY, "polygon", group))
                i += n
                continue
        elif it.command in (_INCL_CIRCLE, _EXCL_CIRCLE):
            out.append((it.command == _INCL_CIRCLE, "circle", [it]))
        i += 1
    return out


def breach(items: Sequence[MissionItem], lat: float, lon: float) -> str | None:
    """Why (lat, lon) is outside the fence ``items`` (None: inside, or no fence)."""
    for inclusion, kind, group in zones(items):
        if kind == "circle":
            c = group[0]
            inside = math.hypot(*flat_ne(c.lat_deg, c.lon_deg, lat, lon)) <= c.param1
        else:
            inside = _inside_polygon(group, lat, lon)
        if inclusion and not inside:
            return f"outside the inclusion {kind} from item {group[0].seq}"
        if not inclusion and inside:
            return f"inside the exclusion {kind} from item {group[0].seq}"
    return None
