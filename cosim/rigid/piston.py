"""The compiler of a ``piston_engine`` and its fixed-pitch ``propeller``
for ``cosim.rigid.propulsion``: ``FGPiston``'s and ``FGPropeller``'s
constructors (the numbers read with their defaults, the derived constants
as JSBSim computes them, the one-dimensional tables) giving the
``Piston`` and ``Propeller`` of ``cosim.rigid.piston_plan``; what they
refuse is said in ``cosim.rigid.propulsion``."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from cosim.rigid.functions import CompileError, _where, table1_data
from cosim.rigid.piston_plan import (
    FTTOM,
    IN3TOM3,
    INHGTOPA,
    MIXTURE_TABLE,
    STANDARD_PRESSURE,
    Piston,
    Propeller,
    Table,
)
from cosim.rigid.propulsion_xml import children, number_in, triplet

#: the piston's numbers: (JSBSim's unit, default); a None default is
#: computed (JSBSim's constructor). Read but feeding only what is not
#: computed (the cylinder head, exhaust gas and oil temperatures): _PISTON_UNUSED
_PISTON_NUMBERS: dict[str, tuple[str, float | None]] = {
    "minmp": ("INHG", 6.5), "maxmp": ("INHG", 28.5), "man-press-lag": ("", 1.0),
    "displacement": ("IN3", 360.0), "maxhp": ("HP", 200.0), "static-friction": ("HP", 1.5),
    "sparkfaildrop": ("", None), "cycles": ("", 4.0), "idlerpm": ("", 600.0),
    "maxrpm": ("", 2800.0), "maxthrottle": ("", 1.0), "minthrottle": ("", 0.0),
    "bsfc": ("LBS/HP*HR", None), "volumetric-efficiency": ("", 0.85),
    "compression-ratio": ("", 8.5), "stroke": ("IN", 4.375),
    "air-intake-impedance-factor": ("", None), "ram-air-factor": ("", 1.0),
    "starter-rpm": ("", None), "starter-torque": ("", None), "dynamic-fmep": ("PA", 18400.0),
    "static-fmep": ("PA", 46500.0), "peak-piston-speed": ("", 100.0)}
_PISTON_UNUSED = {"bore", "cylinders", "cylinder-head-mass", "cooling-factor",
                  "oil-pressure-relief-valve-psi", "design-oil-temp-degK",
                  "oil-pressure-rpm-max", "oil-viscosity-index"}
_PROPELLER_NUMBERS = {"ixx": "SLUG*FT2", "diameter": "FT", "numblades": "", "gearratio": "",
                      "minpitch": "", "maxpitch": "", "ct_factor": "", "cp_factor": ""}
_PROPELLER_TABLES = ("C_THRUST", "C_POWER", "CT_MACH", "CP_MACH")


def _table1(el: ET.Element, source: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """An engine file's table of one dimension (``type="internal"``: no lookup)."""
    extra = [c for c in children(el) if c.tag != "tableData"]
    if extra or len(el.findall("tableData")) != 1:
        raise CompileError(f"{_where(extra[0] if extra else el, source)}: only a table of "
                           f"one dimension (one <tableData>) is supported here")
    data = el.find("tableData")
    assert data is not None
    bp, val = table1_data(data, source)
    return tuple(bp.tolist()), tuple(val.tolist())


def compile_piston(el: ET.Element, index: int, source: str, propeller: Propeller,
                   feeds: tuple[int, ...], problems: list[CompileError] | None) -> Piston:
    """``FGPiston``'s constructor: the numbers read, the defaults and the
    derived constants (impedances, ISFC) as JSBSim computes them."""
    values: dict[str, float] = {}
    mixture: Table = MIXTURE_TABLE
    for c in children(el):
        try:
            if c.tag in _PISTON_NUMBERS:
                values[c.tag] = number_in(c, source, _PISTON_NUMBERS[c.tag][0])
            elif c.tag in _PISTON_UNUSED:
                number_in(c, source)
            elif c.tag == "table" and c.get("name") == "MIXTURE":
                mixture = _table1(c, source)
            elif c.tag == "table" and c.get("name") == "COMBUSTION":
                _table1(c, source)  # the exhaust gas temperature's only
            else:
                raise CompileError(f"{_where(c, source)}: not supported in a piston_engine "
                                   f"(supported: {', '.join(sorted(_PISTON_NUMBERS))}, "
                                   f"{', '.join(sorted(_PISTON_UNUSED))}, tables MIXTURE and "
                                   f"COMBUSTION; no supercharger, no functions)")
        except CompileError as err:
            if problems is None:
                raise
            problems.append(err)

    def get(name: str) -> float:
        v = values.get(name, _PISTON_NUMBERS[name][1])
        assert v is not None
        return v

    min_mp, max_mp, max_rpm, idle_rpm = get("minmp"), get("maxmp"), get("maxrpm"), get("idlerpm")
    stroke, ve, cycles, peak = get("stroke"), get("volumetric-efficiency"), get("cycles"), \
        get("peak-piston-speed")
    displacement, max_hp, friction = get("displacement"), get("maxhp"), get("static-friction")
    fmep_dynamic, fmep_static = get("dynamic-fmep"), get("static-fmep")
    displacement_m3 = displacement * IN3TOM3
    rated_mps = (max_rpm * stroke) / 360
    isfc = values.get("bsfc", -1.0)
    if isfc < 0:
        pmep = (29.92 - max_mp) * INHGTOPA * ve
        fmep = fmep_dynamic * rated_mps * FTTOM + fmep_static
        hp_loss = ((pmep + fmep) * displacement_m3 * max_rpm) / (cycles * 22371)
        isfc = (1.1 * displacement * max_rpm * ve * (max_mp / 29.92)) / (
            9411 * (max_hp + hp_loss - friction))
    max_mp = min(max_mp, 29.9) if max_mp > 29.9 else max_mp
    min_map, max_map = min_mp * INHGTOPA, max_mp * INHGTOPA
    z_airbox = values.get("air-intake-impedance-factor", -999.0)
    if z_airbox < 0.0:
        ze = peak / rated_mps
        z_airbox = (STANDARD_PRESSURE * ze / max_map) - ze
    z_throttle = (peak / ((idle_rpm * stroke) / 360)) * (STANDARD_PRESSURE / min_map - 1) - z_airbox
    drop = values.get("sparkfaildrop")
    return Piston(
        index=index, name=el.get("name", ""), min_throttle=get("minthrottle"),
        max_throttle=get("maxthrottle"), idle_rpm=idle_rpm, max_rpm=max_rpm, stroke_in=stroke,
        cycles=cycles, displacement_m3=displacement_m3, isfc=isfc, volumetric_efficiency=ve,
        compression_ratio=get("compression-ratio"), peak_piston_speed_fps=peak,
        z_airbox=z_airbox, z_throttle=z_throttle, man_press_lag_s=get("man-press-lag"),
        ram_air_factor=get("ram-air-factor"), fmep_dynamic_pa=fmep_dynamic,
        fmep_static_pa=fmep_static, static_friction_hp=friction,
        spark_fail_drop=1.0 if drop is None else min(max(0.0, 1 - drop), 1.0),
        starter_rpm=values.get("starter-rpm", 2 * idle_rpm) if values.get(
            "starter-rpm", -1.0) >= 0.0 else 2 * idle_rpm,
        starter_torque=values.get("starter-torque", max_hp * 0.4) if values.get(
            "starter-torque", -1.0) >= 0 else max_hp * 0.4,
        mixture=mixture, feeds=feeds, propeller=propeller)


def compile_propeller(th: ET.Element, root: ET.Element, path: str, source: str) -> Propeller:
    """``FGPropeller``'s constructor for a fixed-pitch propeller along the
    body's x axis (``th``: the aircraft file's <thruster>; ``root``: the
    propeller file's <propeller>)."""
    values: dict[str, float] = {}
    tables: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {}
    extra = sorted(a for a in root.attrib if a not in ("_line", "name", "version"))
    if extra:
        raise CompileError(f"{_where(root, path)}: attribute {extra[0]!r} is not supported")
    for c in children(root):
        if c.tag in _PROPELLER_NUMBERS:
            values[c.tag] = number_in(c, path, _PROPELLER_NUMBERS[c.tag])
        elif c.tag == "table" and c.get("name") in _PROPELLER_TABLES:
            tables[c.get("name", "")] = _table1(c, path)
        else:
            raise CompileError(f"{_where(c, path)}: not supported in a propeller (supported: "
                               f"{', '.join(sorted(_PROPELLER_NUMBERS))}, tables "
                               f"{', '.join(_PROPELLER_TABLES)} of one dimension: a fixed-pitch "
                               f"propeller)")
    if values.get("minpitch", 0.0) != values.get("maxpitch", 0.0):
        raise CompileError(f"{_where(root, path)}: a variable-pitch propeller (minpitch "
                           f"{values.get('minpitch', 0.0)} != maxpitch "
                           f"{values.get('maxpitch', 0.0)}) is not compiled (fixed pitch only)")
    missing = [t for t in ("C_THRUST", "C_POWER") if t not in tables]
    if missing:
        raise CompileError(f"{_where(root, path)}: needs the table {missing[0]}")
    for c in children(th):
        if c.tag not in ("location", "orient", "sense", "p_factor"):
            raise CompileError(f"{_where(c, source)}: not supported in a propeller thruster "
                               f"(supported: location, orient, sense, p_factor)")
    loc, orient = th.find("location"), th.find("orient")
    if loc is None:
        raise CompileError(f"{_where(th, source)}: needs a <location>")
    if orient is not None and any(triplet(orient, source, "RAD", ("roll", "pitch", "yaw"))):
        raise CompileError(f"{_where(orient, source)}: a propeller turned off the body's x "
                           f"axis is not compiled (roll, pitch and yaw must be 0)")
    sense_el, pf_el = th.find("sense"), th.find("p_factor")
    sense = 1.0 if sense_el is None else (1.0 if number_in(sense_el, source) >= 0.0 else -1.0)
    p_factor = 0.0 if pf_el is None else number_in(pf_el, source)
    if p_factor < 0:
        assert pf_el is not None
        raise CompileError(f"{_where(pf_el, source)}: the P-factor must be 0 or more")
    version = root.get("version")
    try:
        newer = version is not None and float(version) > 1.0
    except ValueError:
        raise CompileError(f"{_where(root, path)}: version {version!r} is not a number") from None
    return Propeller(
        diameter_ft=max(values.get("diameter", 0.0), 0.001),
        ixx_slugft2=max(values.get("ixx", 0.0), 1e-06),
        gear_ratio=max(values.get("gearratio", 1.0), 0.001), ct=tables["C_THRUST"],
        cp=tables["C_POWER"], ct_mach=tables.get("CT_MACH"), cp_mach=tables.get("CP_MACH"),
        ct_factor=values.get("ct_factor", 1.0), cp_factor=values.get("cp_factor", 1.0),
        sense=sense, sense_multiplier=-1.0 if newer else 1.0, p_factor=p_factor,
        location_in=triplet(loc, source, "IN", ("x", "y", "z")))
