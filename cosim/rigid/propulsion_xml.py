"""The XML readers ``cosim.rigid.propulsion``'s compilers share (the
turbine's and the tanks' there, the piston's and the propeller's in
``cosim.rigid.piston``): an element's children, its number in a unit, a
triplet, an engine or thruster file found as JSBSim finds it. It holds no
engine."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from cosim.rigid.functions import CompileError, _where
from cosim.rigid.units import factor, number


def children(el: ET.Element) -> list[ET.Element]:
    """An element's children but its descriptions."""
    return [c for c in el if c.tag != "description"]


def number_in(el: ET.Element, source: str, target: str = "") -> float:
    """An element's number, in ``target`` units (none: as written)."""
    return number(el, source) * unit_factor(el, source, target)


def unit_factor(el: ET.Element, source: str, target: str) -> float:
    """The factor from the element's ``unit`` to ``target`` (none: 1)."""
    return factor(el.get("unit", ""), target, el, source) if target else 1.0


def triplet(el: ET.Element, source: str, target: str, names: tuple[str, str, str]
            ) -> tuple[float, float, float]:
    """``FindElementTripletConvertTo``: three children in the parent's unit."""
    extra = [c for c in children(el) if c.tag not in names]
    if extra:
        raise CompileError(f"{_where(extra[0], source)}: not supported in <{el.tag}> "
                           f"(expected {', '.join(names)})")
    f = unit_factor(el, source, target)
    out = []
    for name in names:
        item = el.find(name)
        out.append(0.0 if item is None else number_in(item, source) * f)
    return out[0], out[1], out[2]


def find_file(name: str, aircraft_dir: Path, engine_dir: Path, el: ET.Element,
              source: str) -> Path:
    """``FGPropulsion::FindFullPathName`` for an engine or thruster file."""
    file = name if name.endswith(".xml") else name + ".xml"
    dirs = [aircraft_dir / d for d in ("Engines", "engines", "Engine", "engine")]
    for d in [*dirs, engine_dir]:
        if (d / file).is_file():
            return d / file
    raise CompileError(f"{_where(el, source)}: file {file!r} not found in "
                       f"{', '.join(str(d) for d in dirs)} or {engine_dir}")
