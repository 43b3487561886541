"""A JSBSim aircraft definition compiled whole: ``compile_aircraft`` reads
the aircraft file and the files it names (engines, thrusters, systems) and
returns a ``RigidAircraft``, a stateless plan that advances any number of
aircraft of that type together, one physics frame at a time, in the order
JSBSim's ``FGFDMExec::Run`` runs its models:

1. propagate the state with the derivatives of the previous frame;
2. the atmosphere at the new altitude; no wind;
3. the systems and the flight controls (the autopilot among them);
4. the mass balance; 5. the auxiliary values (airspeeds, angles);
6. the propulsion; 7. the aerodynamics;
8. the ground: contact is detected, not modelled (see ``touching``);
9. the total force and moment, and the accelerations.

Every value lives in one dict of arrays (``props``) keyed by JSBSim's
property names, one value per aircraft, so a batch's state is that dict:
it is saved, restored or cut to some rows as one unit.

``problems(path)`` lists every element the compiler refuses, for
``cosim models --check``.
"""

from __future__ import annotations

import functools
import logging
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.rigid import atmosphere as geo
from cosim.rigid import body
from cosim.rigid.airframe import (
    Aerodynamics,
    MassBalance,
    Metrics,
    Tank,
    read_aerodynamics,
    read_mass_balance,
    read_metrics,
    structural_to_body,
)
from cosim.rigid.atmosphere import Atmosphere
from cosim.rigid.fcs import Systems, compile_systems
from cosim.rigid.functions import CompileError, parse
from cosim.rigid.propulsion import Propulsion, compile_propulsion
from cosim.rigid.units import IN_TO_FT, triplet_in

logger = logging.getLogger(__name__)
#: FGAuxiliary's heights over the wingspan, computed when a part reads one
_OVER_SPAN = frozenset({"aero/h_b-cg-ft", "aero/h_b-mac-ft"})
Props = dict[str, np.ndarray]

#: sections the compiler reads; anything else at the top level is refused
#: (``fileheader`` only describes; ``ground_reactions`` gives contact points)
_SECTIONS = {"fileheader", "metrics", "mass_balance", "ground_reactions", "propulsion",
             "system", "flight_control", "aerodynamics", "autopilot"}
#: the atmosphere's outputs the body's auxiliary values read (the others,
#: pressure and density altitudes, viscosities and ratios, only when a part
#: reads them)
_AIR_BODY = frozenset({"atmosphere/T-R", "atmosphere/P-psf", "atmosphere/rho-slugs_ft3",
                       "atmosphere/a-fps"})
#: the trim's residuals' scales (ft/s^2, ft/s^2, rad/s^2) for its step control;
#: with the lateral trim, then (rad/s^2, rad/s^2, ft/s^2)
_TRIM_SCALE = np.array([1.0, 1.0, 0.1])
_LATERAL_SCALE = np.array([1.0, 1.0, 0.1, 0.1, 0.1, 1.0])


@dataclass(frozen=True)
class RigidAircraft:
    """One aircraft type, compiled (see the module docstring)."""

    name: str
    source: str
    metrics: Metrics
    mass: MassBalance
    aero: Aerodynamics
    systems: Systems
    propulsion: Propulsion
    atmosphere: Atmosphere
    #: the contact points (structural frame, in)
    contacts: tuple[tuple[float, float, float], ...]
    #: every property some part reads (an output nobody reads may be skipped)
    reads: frozenset[str] = frozenset()

    def new_props(self, n: int) -> Props:
        """Fresh state for ``n`` aircraft: every constant and default, no
        position yet (``place`` sets it)."""
        props: Props = {"_n": np.zeros(n)}
        for k, v in self.metrics.constants().items():
            props[k] = np.full(n, v)
        props["position/terrain-elevation-asl-ft"] = np.zeros(n)
        props["forces/fbz-gear-lbs"] = np.zeros(n)  # no gear forces: the tier stops at contact
        self.atmosphere.init(props, n)
        self.systems.init(props, n)
        self.propulsion.init(props, n)
        self.aero.init(props, n)
        self.mass.run(props)
        return props

    @functools.cached_property
    def property_names(self) -> frozenset[str]:
        """The public properties of this model's state (what a scenario may
        write: JSBSim's names); made once a plan, as a scenario's check asks
        for every vehicle a ``set:`` names."""
        return frozenset(k for k in self.new_props(1) if not k.startswith("_"))

    def place(self, props: Props, loc_ecef_ft: tuple[np.ndarray, np.ndarray, np.ndarray],
              phi: np.ndarray, theta: np.ndarray, psi: np.ndarray,
              uvw: tuple[np.ndarray, np.ndarray, np.ndarray],
              pqr: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
              dt_s: float = 1 / 120) -> None:
        """The initial conditions, then one frame with the integration held
        (FGFDMExec::RunIC: the flight controls run twice at the physics
        step ``dt_s``, the rest once with none), then the past derivatives
        set to the present."""
        z = np.zeros(len(phi))
        body.initial_state(props, loc_ecef_ft, phi, theta, psi, uvw, pqr or (z, z, z))
        self._models(props, 0.0, ic_dt_s=dt_s)
        body.initialize_derivatives(props)

    def trim_level(self, props: Props, loc_ecef_ft: tuple[np.ndarray, np.ndarray, np.ndarray],
                   psi: np.ndarray, vt_fps: np.ndarray, *, iterations: int = 30,
                   tolerance: float = 1e-7, dt_s: float = 1 / 120) -> np.ndarray:
        """Trim every aircraft for straight and level flight at true airspeed
        ``vt_fps`` and heading ``psi`` (rad): the angle of attack (= pitch),
        the throttle (``fcs/throttle-cmd-norm``, the engine at its steady
        state) and the pitch trim (``fcs/pitch-trim-cmd-norm``) that zero the
        forward, vertical and pitch accelerations, by Newton's method with a
        finite-difference Jacobian, wings level and no sideslip (JSBSim's
        full trim also balances the small roll and yaw moments of the
        Earth's rotation: within a few hundredths of a degree). An aircraft
        with a propeller, whose torque and P-factor roll and yaw it in level
        flight (``Propulsion.lateral_trim``: an engine's thruster that
        rolls and yaws the airframe), is trimmed as JSBSim's full trim does
        it: the aileron (``fcs/aileron-cmd-norm``), the rudder
        (``fcs/rudder-cmd-norm``) and the bank also, zeroing the roll, yaw
        and sideways accelerations, the pitch then that of level flight at
        the bank. Returns whether each
        aircraft converged; the state is placed at the result."""
        n = len(psi)
        lateral = self.propulsion.lateral_trim
        size = 6 if lateral else 3
        scale = _LATERAL_SCALE if lateral else _TRIM_SCALE
        x = np.zeros((n, size))
        x[:, 1] = 0.5
        lo = np.array([-0.3, 0.0, -1.0, -1.0, -1.0, -0.5][:size])
        hi = np.array([0.5, 1.0, 1.0, 1.0, 1.0, 0.5][:size])

        def residual(xv: np.ndarray) -> np.ndarray:
            a = xv[:, 0]
            props["fcs/throttle-cmd-norm"] = xv[:, 1].copy()
            props["fcs/pitch-trim-cmd-norm"] = xv[:, 2].copy()
            z = np.zeros(n)
            phi, theta = z, a
            if lateral:
                props["fcs/aileron-cmd-norm"] = xv[:, 3].copy()
                props["fcs/rudder-cmd-norm"] = xv[:, 4].copy()
                phi = xv[:, 5]
                theta = np.arctan(np.cos(phi) * np.tan(a))  # level: no climb at the bank
            uvw = (vt_fps * np.cos(a), z, vt_fps * np.sin(a))
            for settle in (True, False):
                for k in ("accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2",
                          "accelerations/wdot-ft_sec2"):
                    props[k] = z  # trimmed, they are zero (the angle-of-attack rate reads them)
                self.place(props, loc_ecef_ft, phi, theta, psi, uvw, dt_s=dt_s)
                if settle:
                    self.steady_engines(props)
            keys = ["accelerations/udot-ft_sec2", "accelerations/wdot-ft_sec2",
                    "accelerations/qdot-rad_sec2"]
            if lateral:
                keys += ["accelerations/pdot-rad_sec2", "accelerations/rdot-rad_sec2",
                         "accelerations/vdot-ft_sec2"]
            return np.stack([props[k] for k in keys], axis=1)

        h = np.full(size, 1e-6)
        r = residual(x)
        norm = np.linalg.norm(r / scale, axis=1)
        for _ in range(iterations):
            ok = np.all(np.abs(r) < tolerance, axis=1)
            if ok.all():
                break
            jac = np.empty((n, size, size))
            for k in range(size):
                xp = x.copy()
                xp[:, k] += h[k]
                jac[:, :, k] = (residual(xp) - r) / h[k]
            singular = ~np.isfinite(jac).all(axis=(1, 2)) | (np.abs(np.linalg.det(jac)) < 1e-300)
            jac[singular] = np.eye(size)
            step = np.linalg.solve(jac, -r[:, :, None])[:, :, 0]
            step[ok | singular] = 0.0
            # backtracking: halve the step of an aircraft until its residual falls
            frac = np.ones(n)
            for _ in range(8):
                xn = np.clip(x + frac[:, None] * step, lo, hi)
                rn = residual(xn)
                nn = np.linalg.norm(rn / scale, axis=1)
                better = (nn < norm) | ok
                if better.all():
                    break
                frac = np.where(better, frac, 0.5 * frac)
            x = np.where(better[:, None], xn, x)
            r = np.where(better[:, None], rn, r)
            norm = np.where(better, nn, norm)
        r = residual(x)
        return np.all(np.abs(r) < max(tolerance, 1e-5), axis=1)

    def steady_engines(self, props: Props, dt_s: float = 0.1, most: int = 600) -> None:
        """Run the engines alone until they settle at their throttle (as
        JSBSim's trim takes the propulsion's steady state): until no thrust,
        spool or propeller speed or manifold pressure moves by more than
        1e-10 of itself in two steps running (the thrust of a step is that of
        the speed the step began with)."""
        keys = sorted(k for k in self.propulsion.outputs
                      if k.endswith(("thrust-lbs", "/n1", "/n2", "propeller-rpm", "map-pa")))
        still = 0
        for _ in range(most):
            before = [props[k].copy() for k in keys]
            self.propulsion.run(props, dt_s, trimming=True)
            same = all(np.all(np.abs(props[k] - b) <= 1e-10 * np.abs(b) + 1e-12)
                       for k, b in zip(keys, before, strict=True))
            still = still + 1 if same else 0
            if still >= 2:
                break

    def run(self, props: Props, dt_s: float) -> None:
        """One physics frame for every aircraft."""
        body.propagate(props, dt_s)
        self._models(props, dt_s)

    def _models(self, props: Props, dt_s: float, ic_dt_s: float | None = None) -> None:
        self.atmosphere.run(props, dt_s)
        if ic_dt_s is None:
            self.systems.run(props, dt_s)
        else:
            self.systems.run_ic(props, ic_dt_s)
        self.mass.run(props)
        body.auxiliary(props, self.reads)
        if self.reads & _OVER_SPAN:
            self._over_span(props)
        self.propulsion.run(props, dt_s)
        m = self.metrics
        self.aero.run(props, m.rp_in, m.sw_sqft, m.bw_ft, m.cbar_ft, m.iw_rad)
        body.accelerations(props)

    def _over_span(self, props: Props) -> None:
        """FGAuxiliary's heights above the ground over the wingspan (the
        ground effect's lookup): of the CG, and of the aerodynamic reference
        point (its arm from the CG in body axes, the exact inch, turned to
        the local vertical)."""
        agl, span_ft = props["position/h-agl-ft"], self.metrics.bw_ft
        rp = self.metrics.rp_in
        arm = (IN_TO_FT * (props["inertia/cg-x-in"] - rp[0]),
               IN_TO_FT * (rp[1] - props["inertia/cg-y-in"]),
               IN_TO_FT * (props["inertia/cg-z-in"] - rp[2]))
        t = [props["_eom/tl2b_t" + k] for k in ("13", "23", "33")]  # body -> down
        down = t[0] * arm[0] + t[1] * arm[1] + t[2] * arm[2]
        props["aero/h_b-cg-ft"] = agl / span_ft
        props["aero/h_b-mac-ft"] = (agl - down) / span_ft

    def touching(self, props: Props) -> np.ndarray:
        """Whether each aircraft touches the ground: a contact point at or
        below the terrain, or the centre of gravity there (the JSBSim tier's
        rule, without the gear's forces: the tier ends a flight there)."""
        agl = props["position/h-agl-ft"]
        out = agl <= 0.0
        cg = (props["inertia/cg-x-in"], props["inertia/cg-y-in"], props["inertia/cg-z-in"])
        t = [props["_eom/tl2b_t" + k] for k in ("13", "23", "33")]  # body -> down
        for c in self.contacts:
            bx, by, bz = structural_to_body(c, *cg)
            down = t[0] * bx + t[1] * by + t[2] * bz
            out = out | (agl - down <= 0.0)
        return out


def _contacts(root: ET.Element, source: str,
              problems: list[CompileError] | None) -> tuple[tuple[float, float, float], ...]:
    gr = root.find("ground_reactions")
    if gr is None:
        return ()
    out = []
    for c in gr:
        if c.tag == "description":
            continue
        loc = c.find("location")
        if c.tag != "contact" or loc is None:
            err = CompileError(f"{source}:{c.get('_line', '?')}: <{c.tag}>: only <contact> "
                               f"elements with a <location> are read in <ground_reactions>")
            if problems is None:
                raise err
            problems.append(err)
            continue
        out.append(triplet_in(loc, "IN", source))
    return tuple(out)


def compile_aircraft(aircraft_xml: Path, systems_dir: Path, engine_dir: Path, *,
                     problems: list[CompileError] | None = None,
                     fuse: bool = True) -> RigidAircraft:
    """Compile an aircraft file (and the files it names); with ``problems``
    a list, every refusal is appended and compiling goes on where it can.
    ``fuse``: the systems as generated numba loops where they can be (off for
    a check that only lists refusals)."""
    path = Path(aircraft_xml)
    source = str(path)
    root = parse(path)
    for el in root:
        if el.tag not in _SECTIONS:
            err = CompileError(f"{source}:{el.get('_line', '?')}: <{el.tag}>: not supported "
                               f"(the rigid-body tier reads {', '.join(sorted(_SECTIONS))})")
            if problems is None:
                raise err
            problems.append(err)
    metrics = read_metrics(root, source, problems)
    mass = read_mass_balance(root, source, problems)
    aero = read_aerodynamics(root, source, problems)
    systems = compile_systems(path, Path(systems_dir), problems=problems, fuse=fuse)
    prop = compile_propulsion(path, Path(engine_dir), problems=problems)
    mass = mass.with_tanks([Tank(t.location_in, t.contents_key) for t in prop.tanks])
    reads = systems.inputs | aero.inputs | prop.inputs
    # the atmosphere's outputs the body reads, and those some part reads
    air = Atmosphere(_AIR_BODY | (reads & frozenset(geo.FRAME_OUTPUTS)))
    return RigidAircraft(root.get("name", path.stem), source, metrics, mass, aero, systems,
                         prop, air, _contacts(root, source, problems), reads)


def problems(aircraft_xml: Path, systems_dir: Path, engine_dir: Path) -> list[CompileError]:
    """Every element of an aircraft (and its files) the compiler refuses."""
    found: list[CompileError] = []
    try:
        compile_aircraft(aircraft_xml, systems_dir, engine_dir, problems=found, fuse=False)
    except CompileError as err:
        found.append(err)
    unique: dict[str, CompileError] = {}
    for e in found:  # an engine file used twice says its refusals once
        unique.setdefault(str(e), e)
    return list(unique.values())


def position_ecef(lat_geod_deg: np.ndarray, lon_deg: np.ndarray, h_sl_ft: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Earth-fixed position (ft) of a geodetic latitude, a longitude and
    JSBSim's height above sea level (``position/h-sl-ft``: the radius less
    the sea-level radius, not the height above the ellipsoid: they differ by
    a few hundredths of a foot), to a micro-foot."""
    lat, lon = np.radians(lat_geod_deg), np.radians(lon_deg)
    h = np.asarray(h_sl_ft, dtype=np.float64)
    target = h
    for _ in range(4):
        loc = geo.geodetic_to_ecef(lon, lat, h)
        h = h - (geo.altitude_asl_ft(*loc) - target)
    return geo.geodetic_to_ecef(lon, lat, h)


def set_values(props: Props, values: Mapping[str, float | np.ndarray]) -> None:
    """Write properties (a number for every aircraft, or an array)."""
    n = len(props["_n"])
    for k, v in values.items():
        props[k] = np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)).copy()
