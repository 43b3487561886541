"""What stands on the ground to be seen: the scenario's ``targets:`` section
-> ``TargetSpec``s (a truck, a fire truck, a car, a person, a fire), placed in
the scenario's local frame (north/east metres) or by latitude and longitude.

::

    targets:
      - {id: t1, kind: truck, north_m: 0, east_m: 0, heading_deg: 30}
      - {id: f, kind: fire, lat_deg: 37.01, lon_deg: -116.0, growth_m_per_min: 1}

Sizes and colours default by kind (``TARGET_DEFAULTS``); a fire's burning
patch may grow. The renderer draws them (``cosim.renderer``); other sections
add targets of their own through the world (``cosim.world``: the search's
fires), never by editing this section.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

from cosim.core.geo import MAX_DISTANCE_M
from cosim.core.limits import MAX_NAME_CHARS
from cosim.core.section import SectionContext

P = tuple[Any, ...]
#: target ids (and camera names) become parts of file names, as vehicle ids
NAME = re.compile(rf"^[A-Za-z0-9_\-][A-Za-z0-9_.\-]{{0,{MAX_NAME_CHARS - 1}}}$")

#: targets: the largest box side (m)
MAX_TARGET_M = 1000.0

TARGET_KINDS = ("truck", "fire_truck", "car", "person", "fire")

#: kind -> (length_m, width_m, height_m, (r, g, b)) defaults
TARGET_DEFAULTS: dict[str, tuple[float, float, float, tuple[int, int, int]]] = {
    "truck": (10.0, 2.5, 3.5, (200, 200, 195)),  # white box truck
    "fire_truck": (10.0, 2.5, 3.2, (220, 20, 25)),  # signal red with a yellow-green band
    "car": (4.5, 1.8, 1.5, (40, 70, 160)),
    "person": (0.5, 0.4, 1.75, (200, 120, 40)),
    "fire": (8.0, 8.0, 3.0, (255, 120, 0)),  # burning patch; the smoke rises above it
}


@dataclass(frozen=True)
class TargetSpec:
    id: str
    kind: str
    north_m: float | None
    east_m: float | None
    lat_deg: float | None
    lon_deg: float | None
    heading_deg: float
    length_m: float
    width_m: float
    height_m: float
    color_rgb: tuple[int, int, int]
    #: a fire's burning patch grows this fast in length and width (m/s)
    growth_m_per_s: float = 0.0

    def at(self, time_s: float) -> TargetSpec:
        """The target as it is at ``time_s`` (a growing fire's patch larger)."""
        if not self.growth_m_per_s:
            return self
        grow = self.growth_m_per_s * max(0.0, time_s)
        return replace(self, length_m=self.length_m + grow, width_m=self.width_m + grow,
                       growth_m_per_s=0.0)


def rgb(info: SectionContext, v: Any, path: P) -> tuple[int, int, int] | None:
    if isinstance(v, str) and re.match(r"^#[0-9a-fA-F]{6}$", v):
        return int(v[1:3], 16), int(v[3:5], 16), int(v[5:7], 16)
    if (isinstance(v, list) and len(v) == 3
            and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in v)):
        return int(v[0]), int(v[1]), int(v[2])
    info.err(path, f"expected a colour as '#rrggbb' or [r, g, b] (0-255), got {v!r}")
    return None


def parse_targets(info: SectionContext, node: Any, path: P) -> tuple[TargetSpec, ...]:
    if not isinstance(node, list):
        info.err(path, "expected a list of targets")
        return ()
    out: list[TargetSpec] = []
    seen: set[str] = set()
    for i, d in enumerate(node):
        p = path + (i,)
        r = info.reader(d, p, ("id", "kind", "north_m", "east_m", "lat_deg", "lon_deg",
                               "heading_deg", "length_m", "width_m", "height_m", "color",
                               "growth_m_per_min"))
        kind = r.string("kind", choices=TARGET_KINDS)
        tid = r.string("id", f"{kind or 'target'}{i}", pattern=NAME)
        if tid is not None and tid in seen:
            info.err(p + ("id",), f"duplicate target id {tid!r}")
        seen.add(tid or "")
        n = e = la = lo = None
        if r.has("lat_deg") or r.has("lon_deg"):
            if r.has("north_m") or r.has("east_m"):
                info.err(p, "give north_m/east_m or lat_deg/lon_deg, not both")
            la, lo = r.num("lat_deg", lo=-90, hi=90), r.num("lon_deg", lo=-180, hi=180)
        else:
            n = r.num("north_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
            e = r.num("east_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
        dl, dw, dh, dc = TARGET_DEFAULTS.get(kind or "truck", TARGET_DEFAULTS["truck"])
        color = rgb(info, r.d["color"], p + ("color",)) if r.has("color") else dc
        out.append(TargetSpec(
            id=tid or f"target{i}", kind=kind or "truck", north_m=n, east_m=e, lat_deg=la,
            lon_deg=lo, heading_deg=r.num("heading_deg", 0.0, lo=-360, hi=360) or 0.0,
            length_m=r.num("length_m", dl, lo=0.0, lo_open=True, hi=MAX_TARGET_M) or dl,
            width_m=r.num("width_m", dw, lo=0.0, lo_open=True, hi=MAX_TARGET_M) or dw,
            height_m=r.num("height_m", dh, lo=0.0, lo_open=True, hi=MAX_TARGET_M) or dh,
            color_rgb=color or dc,
            growth_m_per_s=(r.num("growth_m_per_min", 0.0, lo=0.0, hi=100.0) or 0.0) / 60.0))
        if out[-1].growth_m_per_s and out[-1].kind != "fire":
            info.err(p + ("growth_m_per_min",), "only a fire grows")
    return tuple(out)
