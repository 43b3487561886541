"""The atmosphere: haze between the cameras and what they see (the
``atmosphere:`` section).

Koschmieder's law: the apparent contrast of an object at distance ``d``
against the horizon sky falls as ``C(d) = C0 exp(-3.912 d / V)``, with ``V``
the meteorological range (``visibility_km``: the distance at which a black
object's contrast has fallen to 2 %, ``ln 50 = 3.912``). A pixel's colour in
linear light becomes ``L = L0 t + A (1 - t)`` with ``t = exp(-3.912 d / V)``
its transmittance and ``A`` the airlight, the horizon's colour (``color``,
default the renderer's horizon sky under the scenario's sun). Without the section there is no haze.
The renderer applies it (``cosim.renderer.haze``); this module owns the
section's keys and the law.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from cosim.core.section import SectionContext

P = tuple[Any, ...]

#: ln 50: Koschmieder's contrast threshold of 2 % at the meteorological range
EXTINCTION = 3.912
#: the meteorological range's limits (km): 50 m is dense fog, 1000 km beyond
#: any real air (the clearest is about 300 km)
VISIBILITY_KM = (0.05, 1000.0)


@dataclass(frozen=True)
class AtmosphereSpec:
    """Haze of meteorological range ``visibility_km`` and airlight ``color_rgb``
    (None: the renderer's horizon sky under the scenario's sun)."""

    visibility_km: float
    color_rgb: tuple[int, int, int] | None = None

    def transmittance(self, distance_m: float) -> float:
        """``t = exp(-3.912 d / V)``: the fraction of an object's contrast left at
        ``distance_m``."""
        return math.exp(-EXTINCTION * distance_m / (1000.0 * self.visibility_km))


def parse_atmosphere(info: SectionContext, node: Any, path: P) -> AtmosphereSpec | None:
    """The ``atmosphere:`` mapping: ``visibility_km`` (required) and ``color``
    (``'#rrggbb'`` or ``[r, g, b]``)."""
    from cosim.world.targets import rgb

    r = info.reader(node, path, ("visibility_km", "color"))
    lo, hi = VISIBILITY_KM
    v = r.num("visibility_km", lo=lo, hi=hi)
    color = rgb(info, r.d["color"], path + ("color",)) if r.has("color") else None
    if v is None or (color is None and r.has("color")):
        return None
    return AtmosphereSpec(float(v), color)
