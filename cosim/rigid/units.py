"""The unit conversions JSBSim applies when it reads an aircraft file, with
its own factors (``FGXMLElement``'s table: a metre is 3.2808399 ft, not
1/0.3048), so a value read here is the double JSBSim holds; and the
constants of its internal units (``FGJSBBase``)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from cosim.rigid.functions import CompileError, _where

M_TO_FT = 3.2808399
KG_TO_LBS = 1.0 / 0.45359237
KG_TO_SLUG = 1.0 / 14.59390
KGM2_TO_SLUGFT2 = 1.0 / 1.35594
#: JSBSim's slug-to-pound factor (the standard gravity in ft/s^2) and inches
SLUG_TO_LB = 32.174049
LB_TO_SLUG = 1.0 / SLUG_TO_LB
IN_TO_FT = 1.0 / 12.0
#: FGJSBBase's own inch-to-foot factor (structural to body frame), truncated as JSBSim has it
INCHTOFT = 0.08333333
#: FGJSBBase's knot (the ``-kts`` properties divide feet per second by it)
KTSTOFPS = 1.68781

#: (supplied unit, target unit) -> factor, as JSBSim defines them
_FACTORS: dict[tuple[str, str], float] = {
    ("M", "FT"): M_TO_FT, ("FT", "M"): 1.0 / M_TO_FT, ("FT", "IN"): 12.0, ("IN", "FT"): IN_TO_FT,
    ("IN", "M"): IN_TO_FT * (1.0 / M_TO_FT), ("M", "IN"): M_TO_FT * 12.0,
    ("CM", "FT"): 0.032808399,
    ("M2", "FT2"): M_TO_FT * M_TO_FT, ("FT2", "M2"): 1.0 / (M_TO_FT * M_TO_FT),
    ("M2", "IN2"): (M_TO_FT * 12.0) ** 2, ("FT2", "IN2"): 144.0, ("IN2", "FT2"): 1.0 / 144.0,
    ("LBS", "KG"): 0.45359237, ("KG", "LBS"): KG_TO_LBS,
    ("SLUG", "KG"): 14.59390, ("KG", "SLUG"): KG_TO_SLUG,
    ("SLUG*FT2", "KG*M2"): 1.35594, ("KG*M2", "SLUG*FT2"): KGM2_TO_SLUGFT2,
    ("RAD", "DEG"): 180.0 / math.pi, ("DEG", "RAD"): 1.0 / (180.0 / math.pi),
    ("LBS/FT", "N/M"): 14.5939, ("N/M", "LBS/FT"): 1.0 / 14.5939,
    ("LBS/FT/SEC", "N/M/SEC"): 14.5939, ("N/M/SEC", "LBS/FT/SEC"): 1.0 / 14.5939,
    ("N", "LBS"): 0.22482, ("LBS", "N"): 1.0 / 0.22482,
    ("KTS", "FT/SEC"): 1.6878098571, ("FT/SEC", "KTS"): 1.0 / 1.6878098571,
    ("M/S", "FT/S"): M_TO_FT, ("M/SEC", "FT/SEC"): M_TO_FT,
    ("L", "GAL"): 0.26417287, ("KG/L", "LBS/GAL"): 8.3454045,
}


def factor(supplied: str, target: str, el: ET.Element, source: str) -> float:
    """The factor JSBSim multiplies a value in ``supplied`` units by to get
    ``target`` units (no unit given: the value is taken as ``target``)."""
    if not supplied or supplied == target:
        return 1.0
    f = _FACTORS.get((supplied, target))
    if f is None:
        known = ", ".join(sorted({target, *(a for a, b in _FACTORS if b == target)}))
        raise CompileError(f"{_where(el, source)}: unit {supplied!r} is not supported here "
                           f"(supported: {known})")
    return f


def number(el: ET.Element, source: str) -> float:
    """An element's single number, or a CompileError naming where."""
    try:
        return float((el.text or "").strip())
    except ValueError:
        raise CompileError(f"{_where(el, source)}: expected a number, got "
                           f"{(el.text or '').strip()!r}") from None


def value_in(parent: ET.Element, tag: str, target: str, source: str,
             default: float | None = None) -> float:
    """The number of ``parent``'s child ``tag`` converted to ``target`` units
    (its own ``unit`` attribute), ``default`` when absent (None: required)."""
    el = parent.find(tag)
    if el is None:
        if default is None:
            raise CompileError(f"{_where(parent, source)}: needs <{tag}>")
        return default
    return number(el, source) * factor(el.get("unit", ""), target, el, source)


def triplet_in(el: ET.Element, target: str, source: str,
               names: tuple[str, str, str] = ("x", "y", "z")) -> tuple[float, float, float]:
    """A ``<location>``/``<orient>``: its three numbers in ``target`` units
    (the unit is the element's attribute; a missing axis is 0, as JSBSim)."""
    f = factor(el.get("unit", ""), target, el, source)
    out = []
    for n in names:
        c = el.find(n)
        out.append(0.0 if c is None else number(c, source) * f)
    return out[0], out[1], out[2]
