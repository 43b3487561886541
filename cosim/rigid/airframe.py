"""An aircraft file's airframe for the rigid-body tier: its metrics, its mass
balance and its aerodynamics, compiled to vectorised plans that compute
what JSBSim's ``FGAircraft``, ``FGMassBalance`` and ``FGAerodynamics``
compute, for every aircraft of a batch at once.

- **Metrics** (``<metrics>``): wing area, span, chord, incidence, tail
  areas and arms, and the aerodynamic reference point, eye point and
  visual reference point, converted with JSBSim's own unit factors; the
  ``metrics/*`` properties.
- **Mass balance** (``<mass_balance>``): the empty weight at its centre of
  gravity with its inertia about that point, point masses and the fuel
  tanks (from the propulsion). Each frame the weight, mass, centre of
  gravity and inertia are summed as JSBSim sums them: the parallel-axis
  terms of every mass about the current centre of gravity, and the inverse
  by JSBSim's closed form.
- **Aerodynamics** (``<aerodynamics>``): its functions (evaluated first,
  in file order) and its six axes. Forces on LIFT, DRAG, SIDE are wind-axis
  forces (drag and lift opposite to the wind axes' x and z) turned into
  body axes with the angle of attack and sideslip; X, Y, Z are body
  forces; ROLL, PITCH, YAW are body moments about the reference point, to
  which the moment of the forces about the centre of gravity is added.
  The stall warning and hysteresis helpers of ``<alphalimits>`` and
  ``<hysteresis_limits>`` are computed as JSBSim does.

Anything else in these sections (``AXIAL``/``NORMAL`` axes, a shifting
reference point, an axis ``frame``, a point mass's shape) is refused with
a ``CompileError`` naming the file, the line and the element.
"""

from __future__ import annotations

import functools
import logging
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from cosim.errors import ConfigError
from cosim.rigid import kernels
from cosim.rigid.body import block
from cosim.rigid.functions import Compiled, CompileError, _where, compile_function
from cosim.rigid.fused import Fused, fuse
from cosim.rigid.units import INCHTOFT, LB_TO_SLUG, triplet_in, value_in

log = logging.getLogger(__name__)
Props = dict[str, np.ndarray]
XYZ = tuple[float, float, float]


def _refuse(problems: list[CompileError] | None, err: CompileError) -> None:
    if problems is None:
        raise err
    problems.append(err)


def _unknown(el: ET.Element, allowed: set[str], source: str,
             problems: list[CompileError] | None) -> None:
    for c in el:
        if c.tag not in allowed and c.tag not in ("description", "documentation"):
            _refuse(problems, CompileError(
                f"{_where(c, source)}: not supported in <{el.tag}> (supported: "
                f"{', '.join(sorted(allowed))})"))


@dataclass(frozen=True)
class Metrics:
    """``<metrics>``: reference geometry (ft, ft^2, rad) and points (in)."""

    sw_sqft: float
    bw_ft: float
    cbar_ft: float
    iw_rad: float = 0.0
    sh_sqft: float = 0.0
    lh_ft: float = 0.0
    sv_sqft: float = 0.0
    lv_ft: float = 0.0
    rp_in: XYZ = (0.0, 0.0, 0.0)
    eye_in: XYZ = (0.0, 0.0, 0.0)
    vrp_in: XYZ = (0.0, 0.0, 0.0)

    def constants(self) -> dict[str, float]:
        """The ``metrics/*`` properties (FGAircraft's)."""
        c = self.cbar_ft
        sw = self.sw_sqft
        lbarh = self.lh_ft / c if c else 0.0
        lbarv = self.lv_ft / c if c else 0.0
        vbarh = self.sh_sqft * lbarh / sw if sw else 0.0
        vbarv = self.sv_sqft * lbarv / sw if sw else 0.0
        return {"metrics/Sw-sqft": sw, "metrics/bw-ft": self.bw_ft, "metrics/cbarw-ft": c,
                "metrics/iw-rad": self.iw_rad, "metrics/iw-deg": math.degrees(self.iw_rad),
                "metrics/Sh-sqft": self.sh_sqft, "metrics/lh-ft": self.lh_ft,
                "metrics/Sv-sqft": self.sv_sqft, "metrics/lv-ft": self.lv_ft,
                "metrics/lh-norm": lbarh, "metrics/lv-norm": lbarv,
                "metrics/vbarh-norm": vbarh, "metrics/vbarv-norm": vbarv,
                "metrics/aero-rp-x-in": self.rp_in[0], "metrics/aero-rp-y-in": self.rp_in[1],
                "metrics/aero-rp-z-in": self.rp_in[2],
                "metrics/eyepoint-x-in": self.eye_in[0], "metrics/eyepoint-y-in": self.eye_in[1],
                "metrics/eyepoint-z-in": self.eye_in[2],
                "metrics/visualrefpoint-x-in": self.vrp_in[0],
                "metrics/visualrefpoint-y-in": self.vrp_in[1],
                "metrics/visualrefpoint-z-in": self.vrp_in[2]}


_METRIC_VALUES = {"wingarea": ("sw_sqft", "FT2"), "wingspan": ("bw_ft", "FT"),
                  "chord": ("cbar_ft", "FT"), "wing_incidence": ("iw_rad", "RAD"),
                  "htailarea": ("sh_sqft", "FT2"), "htailarm": ("lh_ft", "FT"),
                  "vtailarea": ("sv_sqft", "FT2"), "vtailarm": ("lv_ft", "FT")}
_POINTS = {"AERORP": "rp_in", "EYEPOINT": "eye_in", "VRP": "vrp_in"}


def read_metrics(root: ET.Element, source: str,
                 problems: list[CompileError] | None = None) -> Metrics:
    """The aircraft's ``<metrics>``."""
    el = root.find("metrics")
    if el is None:
        raise CompileError(f"{_where(root, source)}: has no <metrics>")
    _unknown(el, set(_METRIC_VALUES) | {"location"}, source, problems)
    kw: dict[str, object] = {}
    for tag, (attr, unit) in _METRIC_VALUES.items():
        if el.find(tag) is not None:
            kw[attr] = value_in(el, tag, unit, source)
    for loc in el.findall("location"):
        name = loc.get("name", "")
        if name not in _POINTS:
            _refuse(problems, CompileError(f"{_where(loc, source)}: location {name!r} is not "
                                           f"supported (AERORP, EYEPOINT, VRP)"))
            continue
        kw[_POINTS[name]] = triplet_in(loc, "IN", source)
    for need in ("sw_sqft", "bw_ft", "cbar_ft"):
        if need not in kw:
            tag = next(t for t, (a, _) in _METRIC_VALUES.items() if a == need)
            raise CompileError(f"{_where(el, source)}: needs <{tag}>")
    return Metrics(**kw)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Tank:
    """A fuel tank as the mass balance sees it: where, and the property
    holding its contents (lbs)."""

    location_in: XYZ
    contents_key: str


@dataclass(frozen=True)
class MassBalance:
    """``<mass_balance>``: the empty aircraft and its point masses; the
    tanks are added by ``run`` (their contents change)."""

    empty_lbs: float
    base_cg_in: XYZ
    #: the empty aircraft's inertia about its own centre of gravity (slug ft^2),
    #: as JSBSim's matrix: (1,1) Ixx, (1,2) -Ixy, (1,3) Ixz... (see read_mass_balance)
    base_j: tuple[tuple[float, float, float], ...]
    pointmasses: tuple[tuple[float, XYZ], ...] = ()
    tanks: tuple[Tank, ...] = field(default=())

    outputs = ("inertia/mass-slugs", "inertia/weight-lbs", "inertia/empty-weight-lbs",
               "inertia/cg-x-in", "inertia/cg-y-in", "inertia/cg-z-in",
               "inertia/ixx-slugs_ft2", "inertia/iyy-slugs_ft2", "inertia/izz-slugs_ft2",
               "inertia/ixy-slugs_ft2", "inertia/ixz-slugs_ft2", "inertia/iyz-slugs_ft2")

    def with_tanks(self, tanks: Sequence[Tank]) -> MassBalance:
        return MassBalance(self.empty_lbs, self.base_cg_in, self.base_j, self.pointmasses,
                           tuple(tanks))

    def run(self, props: Props) -> None:
        """FGMassBalance::Run for every aircraft: weight, mass, CG, J, J^-1
        (the inverse's six terms under ``_mb/jinv*``). Nothing is recomputed
        while every tank holds what it held at the last computation (frozen
        fuel, or an engine off): the sums would give the same doubles."""
        n = len(props["_n"])
        if self._unchanged(props, n):
            return
        w = np.full(n, self.empty_lbs)
        mx = np.full(n, self.empty_lbs * self.base_cg_in[0])
        my = np.full(n, self.empty_lbs * self.base_cg_in[1])
        mz = np.full(n, self.empty_lbs * self.base_cg_in[2])
        pm_w = sum(p[0] for p in self.pointmasses)
        # JSBSim: Weight = EmptyWeight + TanksWeight + PointMassWeight, then
        # CG = (EmptyWeight*cg0 + PointMassMoment + TanksMoment) / Weight
        tank_w = np.zeros(n)
        tx = np.zeros(n)
        ty = np.zeros(n)
        tz = np.zeros(n)
        for t in self.tanks:
            c = props[t.contents_key]
            tank_w = tank_w + c
            tx = tx + t.location_in[0] * c
            ty = ty + t.location_in[1] * c
            tz = tz + t.location_in[2] * c
        weight = w + tank_w + pm_w
        pmx = sum(p[0] * p[1][0] for p in self.pointmasses)
        pmy = sum(p[0] * p[1][1] for p in self.pointmasses)
        pmz = sum(p[0] * p[1][2] for p in self.pointmasses)
        cgx = (mx + pmx + tx) / weight
        cgy = (my + pmy + ty) / weight
        cgz = (mz + pmz + tz) / weight
        props["inertia/weight-lbs"] = weight
        props["inertia/mass-slugs"] = LB_TO_SLUG * weight
        props["inertia/empty-weight-lbs"] = np.full(n, self.empty_lbs)
        props["inertia/cg-x-in"], props["inertia/cg-y-in"], props["inertia/cg-z-in"] = (
            cgx, cgy, cgz)
        j = [[np.full(n, self.base_j[r][c]) for c in range(3)] for r in range(3)]
        masses: list[tuple[np.ndarray | float, XYZ]] = [
            (LB_TO_SLUG * self.empty_lbs, self.base_cg_in)]
        masses += [(LB_TO_SLUG * p[0], p[1]) for p in self.pointmasses]
        masses += [(LB_TO_SLUG * props[t.contents_key], t.location_in) for t in self.tanks]
        for m, loc in masses:
            _add_pointmass(j, m, loc, cgx, cgy, cgz)
        ixx, iyy, izz = j[0][0], j[1][1], j[2][2]
        ixy, ixz, iyz = -j[0][1], -j[0][2], -j[1][2]
        props["inertia/ixx-slugs_ft2"], props["inertia/iyy-slugs_ft2"] = ixx, iyy
        props["inertia/izz-slugs_ft2"] = izz
        props["inertia/ixy-slugs_ft2"], props["inertia/ixz-slugs_ft2"] = ixy, ixz
        props["inertia/iyz-slugs_ft2"] = iyz
        k1 = iyy * izz - iyz * iyz
        k2 = iyz * ixz + ixy * izz
        k3 = ixy * iyz + iyy * ixz
        denom = 1.0 / (ixx * k1 - ixy * k2 - ixz * k3)
        props["_mb/jinv11"] = k1 * denom
        props["_mb/jinv12"] = k2 * denom
        props["_mb/jinv13"] = k3 * denom
        props["_mb/jinv22"] = (izz * ixx - ixz * ixz) * denom
        props["_mb/jinv23"] = (ixy * ixz + iyz * ixx) * denom
        props["_mb/jinv33"] = (ixx * iyy - ixy * ixy) * denom


    def _unchanged(self, props: Props, n: int) -> bool:
        held = [props[t.contents_key] for t in self.tanks]
        last = props.get("_mb/contents")
        same = (last is not None and last.shape == (len(held), n)
                and "_mb/jinv33" in props and len(props["_mb/jinv33"]) == n
                and all(np.array_equal(h, last[k]) for k, h in enumerate(held)))
        if not same:
            props["_mb/contents"] = np.array(held).reshape(len(held), n)
        return same


def _add_pointmass(j: list[list[np.ndarray]], m: np.ndarray | float, loc: XYZ,
                   cgx: np.ndarray, cgy: np.ndarray, cgz: np.ndarray) -> None:
    """J += the inertia of point mass ``m`` (slug) at ``loc`` (in, structural)
    about the centre of gravity (FGMassBalance::GetPointmassInertia)."""
    vx, vy, vz = structural_to_body(loc, cgx, cgy, cgz)
    sx, sy, sz = m * vx, m * vy, m * vz
    xx, yy, zz = sx * vx, sy * vy, sz * vz
    xy, xz, yz = -sx * vy, -sx * vz, -sy * vz
    j[0][0] = j[0][0] + (yy + zz)
    j[0][1] = j[0][1] + xy
    j[0][2] = j[0][2] + xz
    j[1][0] = j[1][0] + xy
    j[1][1] = j[1][1] + (xx + zz)
    j[1][2] = j[1][2] + yz
    j[2][0] = j[2][0] + xz
    j[2][1] = j[2][1] + yz
    j[2][2] = j[2][2] + (xx + yy)


def structural_to_body(loc: XYZ, cgx: np.ndarray, cgy: np.ndarray, cgz: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A structural-frame point (in; x aft, z up) relative to the centre of
    gravity in body axes (ft; x forward, z down), FGMassBalance::StructuralToBody."""
    return (INCHTOFT * (cgx - loc[0]), INCHTOFT * (loc[1] - cgy), INCHTOFT * (cgz - loc[2]))


def read_mass_balance(root: ET.Element, source: str,
                      problems: list[CompileError] | None = None) -> MassBalance:
    """The aircraft's ``<mass_balance>``."""
    el = root.find("mass_balance")
    if el is None:
        raise CompileError(f"{_where(root, source)}: has no <mass_balance>")
    allowed = {"ixx", "iyy", "izz", "ixy", "ixz", "iyz", "emptywt", "location", "pointmass"}
    _unknown(el, allowed, source, problems)
    if el.get("negated_crossproduct_inertia", "true") not in ("true",):
        _refuse(problems, CompileError(f"{_where(el, source)}: negated_crossproduct_inertia="
                                       f"{el.get('negated_crossproduct_inertia')!r} is not "
                                       f"supported"))
    i = {k: value_in(el, k, "SLUG*FT2", source, 0.0)
         for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")}
    base_j = ((i["ixx"], -i["ixy"], i["ixz"]),
              (-i["ixy"], i["iyy"], -i["iyz"]),
              (i["ixz"], -i["iyz"], i["izz"]))
    empty = value_in(el, "emptywt", "LBS", source)
    loc = el.find("location")
    if loc is None or loc.get("name", "CG") != "CG":
        raise CompileError(f"{_where(el, source)}: needs <location name=\"CG\">")
    pms = []
    for pm in el.findall("pointmass"):
        bad = [c for c in pm if c.tag not in ("weight", "location", "description")]
        if bad:
            _refuse(problems, CompileError(f"{_where(bad[0], source)}: not supported in a "
                                           f"<pointmass> (weight and location only)"))
            continue
        ploc = pm.find("location")
        if ploc is None:
            raise CompileError(f"{_where(pm, source)}: needs <location>")
        pms.append((value_in(pm, "weight", "LBS", source), triplet_in(ploc, "IN", source)))
    return MassBalance(empty, triplet_in(loc, "IN", source), base_j, tuple(pms))


# ------------------------------------------------------------ aerodynamics --

_FORCE_AXES = {"LIFT": 2, "DRAG": 0, "SIDE": 1, "X": 0, "Y": 1, "Z": 2}
_MOMENT_AXES = {"ROLL": 0, "PITCH": 1, "YAW": 2}


@dataclass(frozen=True)
class Aerodynamics:
    """The compiled ``<aerodynamics>``: its functions (by output name, in
    order) and each axis's terms."""

    variables: tuple[Compiled, ...]
    forces: tuple[tuple[Compiled, ...], tuple[Compiled, ...], tuple[Compiled, ...]]
    moments: tuple[tuple[Compiled, ...], tuple[Compiled, ...], tuple[Compiled, ...]]
    wind_axes: bool
    alpha_clmax_rad: float = 0.0
    alpha_clmin_rad: float = 0.0
    hyst_min_rad: float = 0.0
    hyst_max_rad: float = 0.0
    #: functions JSBSim evaluates after the model's frame (``type="post"``)
    post: tuple[Compiled, ...] = ()

    @property
    def inputs(self) -> frozenset[str]:
        made = {c.name for c in self.variables}
        every = [*self.variables, *self.post, *(c for a in self.forces for c in a),
                 *(c for a in self.moments for c in a)]
        return frozenset(set().union(*(c.inputs for c in every)) - made)

    @functools.cached_property
    def _fused(self) -> Fused | None:
        """The functions and axis terms as one numba loop (``cosim.rigid.fused``),
        built at the first frame of a process; None: numpy's kernels."""
        every = [*self.variables, *(c for a in self.forces for c in a),
                 *(c for a in self.moments for c in a)]
        groups, k = [], len(self.variables)
        for terms in (*self.forces, *self.moments):
            groups.append(list(range(k, k + len(terms))))
            k += len(terms)
        try:
            return fuse(every, "aerodynamics", name="aero", sums=groups)
        except CompileError as e:  # a function the fuser does not know: numpy's
            log.info("aerodynamics not fused (%s): numpy's kernels", e)
            return None

    def _terms(self, props: Props) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Every function, then each axis's sum (force axes, moment axes)."""
        fz = self._fused
        if fz is None:
            return _numpy_terms(self, props)
        n = len(props["_n"])
        out = fz.run(props, block(props, "_aero/terms", fz.names, n) if fz.names and
                     fz.names[0] else None)
        for k, name in enumerate(fz.names):
            if name:
                props[name] = out[k]
        s = len(fz.names) - 6  # the six axes' sums, left to right from zero
        return [out[s], out[s + 1], out[s + 2]], [out[s + 3], out[s + 4], out[s + 5]]

    def init(self, props: Props, n: int) -> None:
        props["aero/stall-hyst-norm"] = np.zeros(n)
        props["aero/bi2vel"] = np.zeros(n)
        props["aero/ci2vel"] = np.zeros(n)

    def run(self, props: Props, rp_in: XYZ, sw_sqft: float, bw_ft: float, cbar_ft: float,
            iw_rad: float) -> None:
        """FGAerodynamics::Run: the body forces (lbs) and moments about the
        centre of gravity (lbs ft) into ``forces/f?-aero-lbs`` and
        ``moments/?-aero-lbsft``."""
        vt = props["velocities/vt-fps"]
        alpha = props["aero/alpha-rad"]
        qbar = props["aero/qbar-psf"]
        twovel = 2.0 * vt
        moving = twovel != 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            props["aero/bi2vel"] = np.where(moving, bw_ft / twovel, props["aero/bi2vel"])
            props["aero/ci2vel"] = np.where(moving, cbar_ft / twovel, props["aero/ci2vel"])
        props["aero/alpha-wing-rad"] = alpha + iw_rad
        props["aero/qbar-area"] = sw_sqft * qbar
        if self.alpha_clmax_rad != 0.0:
            props["systems/stall-warn-norm"] = np.where(
                alpha > 0.85 * self.alpha_clmax_rad,
                10.0 * (alpha / self.alpha_clmax_rad - 0.85), 0.0)
        if self.hyst_max_rad != 0.0 and self.hyst_min_rad != 0.0:
            h = props["aero/stall-hyst-norm"]
            props["aero/stall-hyst-norm"] = np.where(
                alpha > self.hyst_max_rad, 1.0, np.where(alpha < self.hyst_min_rad, 0.0, h))
        native, mom = self._terms(props)
        keys = kernels.AERO_FORCES if self.wind_axes else kernels.AERO_FORCES[:6]
        out = block(props, "_aero/forces", keys, len(alpha))
        kernels.aero_forces(native[0], native[1], native[2], alpha, props["aero/beta-rad"],
                            mom[0], mom[1], mom[2], props["inertia/cg-x-in"],
                            props["inertia/cg-y-in"], props["inertia/cg-z-in"], rp_in[0],
                            rp_in[1], rp_in[2], INCHTOFT, self.wind_axes, out)
        for j, key in enumerate(keys):
            props[key] = out[j]
        for f in self.post:
            props[f.name] = f.kernel(props)


def _numpy_terms(aero: Aerodynamics, props: Props) -> tuple[list[np.ndarray], list[np.ndarray]]:
    for v in aero.variables:
        props[v.name] = v.kernel(props)
    return ([_sum_terms(terms, props) for terms in aero.forces],
            [_sum_terms(terms, props) for terms in aero.moments])


def _sum_terms(terms: tuple[Compiled, ...], props: Props) -> np.ndarray:
    n = len(props["_n"])
    acc = np.zeros(n)
    for t in terms:
        val = t.kernel(props)
        if t.name:
            props[t.name] = val
        acc = acc + val
    return acc


def read_aerodynamics(root: ET.Element, source: str,
                      problems: list[CompileError] | None = None) -> Aerodynamics:
    """The aircraft's ``<aerodynamics>``, compiled."""
    el = root.find("aerodynamics")
    if el is None:
        raise CompileError(f"{_where(root, source)}: has no <aerodynamics>")
    if el.get("file"):
        raise CompileError(f"{_where(el, source)}: an aerodynamics file is not supported "
                           f"(write the section in the aircraft file)")
    _unknown(el, {"alphalimits", "hysteresis_limits", "function", "axis"}, source, problems)

    def compiled(f: ET.Element) -> Compiled | None:
        try:
            return compile_function(f, source)
        except CompileError as e:
            _refuse(problems, e)
            return None

    def post(f: ET.Element) -> Compiled | None:
        g = ET.Element(f.tag, {k: v for k, v in f.attrib.items() if k != "type"})
        g.extend(list(f))
        return compiled(g)

    funcs = el.findall("function")
    bad = [f for f in funcs if f.get("type", "post") != "post"]
    for f in bad:
        _refuse(problems, CompileError(f"{_where(f, source)}: function type "
                                       f"{f.get('type')!r} is not supported (post only)"))
    variables = tuple(c for c in (compiled(f) for f in funcs if "type" not in f.attrib) if c)
    posts = tuple(c for c in (post(f) for f in funcs if f.get("type") == "post") if c)
    forces: list[list[Compiled]] = [[], [], []]
    moments: list[list[Compiled]] = [[], [], []]
    kinds = set()
    for ax in el.findall("axis"):
        name = ax.get("name", "")
        extra = sorted(a for a in ax.attrib if a not in ("_line", "name", "unit"))
        if extra or ax.get("unit") not in (None, "LBS", "LBS*FT"):
            _refuse(problems, CompileError(
                f"{_where(ax, source)}: axis attribute "
                f"{(extra or ['unit'])[0]!r} is not supported (name only)"))
            continue
        if name in _MOMENT_AXES:
            target = moments[_MOMENT_AXES[name]]
        elif name in _FORCE_AXES:
            kinds.add("wind" if name in ("LIFT", "DRAG", "SIDE") else "body")
            target = forces[_FORCE_AXES[name]]
        else:
            _refuse(problems, CompileError(
                f"{_where(ax, source)}: axis {name!r} is not supported (LIFT, DRAG, SIDE, "
                f"X, Y, Z, ROLL, PITCH, YAW)"))
            continue
        bad = [c for c in ax if c.tag not in ("function", "description")]
        for b in bad:
            _refuse(problems, CompileError(f"{_where(b, source)}: not supported in an <axis>"))
        target.extend(c for c in (compiled(f) for f in ax.findall("function")) if c)
    if len(kinds) > 1:
        raise CompileError(f"{_where(el, source)}: mixes wind (LIFT, DRAG, SIDE) and body "
                           f"(X, Y, Z) force axes")

    def limits(tag: str) -> tuple[float, float]:
        lim = el.find(tag)
        if lim is None:
            return 0.0, 0.0
        unit = lim.get("unit", "RAD")
        factor = 1.0 / (180.0 / math.pi) if unit == "DEG" else 1.0
        if unit not in ("DEG", "RAD"):
            raise ConfigError(f"{_where(lim, source)}: unit {unit!r} (DEG or RAD)")
        return (value_in(lim, "min", "", source) * factor,
                value_in(lim, "max", "", source) * factor)

    amin, amax = limits("alphalimits")
    hmin, hmax = limits("hysteresis_limits")
    ftuple: Callable[[list[Compiled]], tuple[Compiled, ...]] = tuple
    return Aerodynamics(variables,
                        (ftuple(forces[0]), ftuple(forces[1]), ftuple(forces[2])),
                        (ftuple(moments[0]), ftuple(moments[1]), ftuple(moments[2])),
                        "body" not in kinds, amax, amin, hmin, hmax, posts)
