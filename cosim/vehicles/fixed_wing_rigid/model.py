"""The rigid-body fixed-wing batch: every aircraft of a worker flown by its
JSBSim files compiled with ``cosim.rigid`` (six degrees of freedom, the
aircraft's own aerodynamics, engines and autopilot), one vectorised frame
at a time for all of them.

Aircraft of different models in one worker are kept in one group per
model. An aircraft that stops (a ground impact, a landing, a state that is
no longer finite) is taken out of its group's arrays: the others fly on
without it. A ground impact or a landing keeps the row of the frame it
touched; a diverged aircraft keeps the row it had (the last one written, as
the JSBSim tier keeps a diverged vehicle's last state), only its status
changes.

``step_watched`` steps the batch a few frames at a time and writes some
rows between (a camera's aircraft faster than the exchanges): the frames
are the same whatever the pieces, so the states are too.

The ground is the JSBSim tier's rule without the gear's forces: when a
contact point of the aircraft file (or its centre of gravity) reaches the
terrain, it is a landing if the autopilot's ``landing`` flag is set, the
sink is gentle and the wings level (the JSBSim tier's ``LANDING_*``
limits), else a ground impact. A landed aircraft stays where it touched,
at rest (take-off is not modelled).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.core.state import STATE_FIELDS, STATE_INDEX, VehicleSpec, VehicleStatus
from cosim.core.units import FT_TO_M, KT_TO_MPS, LB_TO_KG, LBF_TO_N
from cosim.errors import BuildError, ConfigError
from cosim.rigid.aircraft import RigidAircraft, compile_aircraft, position_ecef
from cosim.rigid.kernels import any_low_or_not_finite
from cosim.vehicles.jsbsim_model import LANDING_PROP, LANDING_ROLL_RAD, LANDING_SINK_FPS

_S = STATE_INDEX
_FPS = 1.0 / FT_TO_M
#: the state columns read from the properties (JSBSim's names and scales)
_READ = [(i, f.prop, f.scale) for i, f in enumerate(STATE_FIELDS) if f.prop]
#: below this height (ft) above the terrain the contact points are checked
_REACH_FT = 30.0
_FINITE = ("position/h-sl-ft", "velocities/vt-fps", "attitude/phi-rad", "attitude/theta-rad",
           "velocities/u-fps", "velocities/p-rad_sec")


@functools.lru_cache(maxsize=16)
def compiled(xml: str, systems_dir: str, engine_dir: str) -> RigidAircraft:
    """A model's files compiled once per process (a plan holds no state)."""
    return compile_aircraft(Path(xml), Path(systems_dir), Path(engine_dir))


@dataclass
class _Group:
    """The aircraft of one model: their rows in the batch and their state."""

    aircraft: RigidAircraft
    rows: np.ndarray  # the batch rows still flying
    props: dict[str, np.ndarray]


class RigidBatch:
    """Every rigid-body fixed-wing of one worker (see the module docstring)."""

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str],
                 columns: Sequence[str]) -> None:
        self.dt = dt_s
        cols = list(columns)
        self.c_contact = cols.index("contact_force_n")
        self.c_fuel = cols.index("fuel_kg")
        self.channels = list(channels)
        self.n = len(specs)
        self.status = np.full(self.n, float(VehicleStatus.ACTIVE))
        #: rows that touched the ground: their row at that frame
        self.frozen: dict[int, np.ndarray] = {}
        #: rows that diverged: they keep the row they had
        self.diverged: list[int] = []
        self.width = len(cols)
        #: a group a model and a start (trimmed or not: a group starts together)
        by_model: dict[tuple[str, str, str, bool], list[int]] = {}
        for r, s in enumerate(specs):
            p = s.class_params
            by_model.setdefault((p["xml"], p["systems_dir"], p["engine_dir"], s.trim),
                                []).append(r)
        #: (vehicle id, why) of the aircraft that could not be trimmed
        self.failures: list[tuple[str, str]] = []
        self.groups = [self._build(compiled(*key[:3]), [specs[r] for r in rows], rows)
                       for key, rows in by_model.items()]
        if self.failures:  # every one, as the JSBSim tier reports its own
            order = {s.id: r for r, s in enumerate(specs)}
            raise BuildError(sorted(self.failures, key=lambda f: order[f[0]]), self.n)

    def _build(self, ac: RigidAircraft, specs: list[VehicleSpec], rows: list[int]) -> _Group:
        m = len(specs)
        props = ac.new_props(m)
        for name, value in specs[0].class_params.get("properties", ()):
            if name not in props:
                raise ConfigError(f"the profile of {specs[0].model!r} sets {name!r}, which "
                                  f"its compiled files lack")
            props[name] = np.full(m, float(value))
        props["position/terrain-elevation-asl-ft"] = np.array(
            [s.terrain_alt_m * _FPS for s in specs])
        loc = position_ecef(np.array([s.lat_deg for s in specs]),
                            np.array([s.lon_deg for s in specs]),
                            np.array([s.alt_msl_m * _FPS for s in specs]))
        psi = np.radians(np.array([s.heading_deg for s in specs]))
        vt = np.array([s.airspeed_mps * _FPS for s in specs])
        if specs[0].trim:  # the group's every aircraft, as grouped
            ok = ac.trim_level(props, loc, psi, vt, dt_s=self.dt)
            for s in (specs[i] for i in np.flatnonzero(~ok)):
                self.failures.append((s.id, (
                    f"vehicle {s.id!r} ({s.model}): the rigid-body tier could not trim at "
                    f"{s.airspeed_mps:.1f} m/s TAS ({s.airspeed_mps / KT_TO_MPS:.0f} kt), "
                    f"{s.alt_msl_m:.1f} m MSL ({s.alt_msl_m - s.terrain_alt_m:.1f} m above "
                    f"the ground): level flight needs an angle of attack, throttle or pitch "
                    f"trim outside the model's range")))
        else:  # the JSBSim tier's untrimmed start: run_ic, then propulsion/set-running
            z = np.zeros(m)
            ac.place(props, loc, z, z, psi, (vt, z, z), dt_s=self.dt)
            ac.propulsion.set_running(props)
        for i, s in enumerate(specs):
            for name, value in s.initial_props:
                if name in props:
                    props[name][i] = value
        return _Group(ac, np.asarray(rows, dtype=np.intp), props)

    def apply(self, setpoints: np.ndarray) -> None:
        """Write the setpoint channels' values (the non-NaN ones) into each
        aircraft's properties (a channel its model lacks is left alone)."""
        for g in self.groups:
            if not len(g.rows):
                continue
            mine = setpoints[g.rows]
            for j, name in enumerate(self.channels):
                col = mine[:, j]
                given = col == col
                if not given.any() or name not in g.props:
                    continue
                g.props[name] = np.where(given, col, g.props[name])

    def step(self, nsub: int) -> None:
        for g in self.groups:
            for _ in range(nsub):
                if not len(g.rows):
                    break
                g.aircraft.run(g.props, self.dt)
                self._ground_and_health(g)

    def _ground_and_health(self, g: _Group) -> None:
        p = g.props
        if not any_low_or_not_finite(p["position/h-agl-ft"], _REACH_FT,
                                     *(p[k] for k in _FINITE)):
            return  # every aircraft high and finite: one pass
        low = p["position/h-agl-ft"] < _REACH_FT
        bad = np.zeros(len(g.rows), dtype=bool)
        for k in _FINITE:
            bad |= ~np.isfinite(p[k])
        if not low.any() and not bad.any():
            return
        touching = low & g.aircraft.touching(p)
        landing = p[LANDING_PROP] >= 0.5 if LANDING_PROP in p else np.zeros(len(g.rows), bool)
        gentle = landing & (p["velocities/v-down-fps"] < LANDING_SINK_FPS) & (
            np.abs(p["attitude/phi-rad"]) < LANDING_ROLL_RAD)
        stop = bad | touching
        if not stop.any():
            return
        rows = g.rows
        block = np.zeros((len(rows), self.width))
        self._write(g, block)
        for i in np.flatnonzero(stop).tolist():
            r = int(rows[i])
            row = block[i].copy()
            if bad[i]:  # its last finite row is the one written before
                self.status[r] = float(VehicleStatus.DIVERGED)
                self.diverged.append(r)
                continue
            if gentle[i]:  # a landing: at rest where it touched
                for c in ("vn_mps", "ve_mps", "vd_mps", "airspeed_mps", "alpha_deg"):
                    row[_S[c]] = 0.0
                row[_S["roll_deg"]] = 0.0
                row[self.c_contact] = float(p["inertia/weight-lbs"][i]) * LBF_TO_N
                row[_S["gear_force_lbs"]] = -float(p["inertia/weight-lbs"][i])
            else:
                row[_S["status"]] = self.status[r] = float(VehicleStatus.GROUND_IMPACT)
            self.frozen[r] = row
        keep = ~stop
        g.rows = rows[keep]
        g.props = {k: v[..., keep] for k, v in p.items()}  # the aircraft are the last axis

    def _write(self, g: _Group, block: np.ndarray, at: np.ndarray | None = None) -> None:
        """The group's rows (``at``: those positions in its arrays only)."""
        p = g.props
        pick = slice(None) if at is None else at
        for j, prop, scale in _READ:
            block[:, j] = p[prop][pick] * scale if prop in p else np.nan
        block[:, _S["status"]] = self.status[g.rows[pick]]
        block[:, self.c_contact] = 0.0
        block[:, self.c_fuel] = (p["propulsion/total-fuel-lbs"][pick] * LB_TO_KG
                                 if "propulsion/total-fuel-lbs" in p else np.nan)

    def write_states(self, out: np.ndarray) -> None:
        for g in self.groups:
            if len(g.rows):
                block = np.empty((len(g.rows), out.shape[1]))
                self._write(g, block)
                out[g.rows] = block
        self._write_stopped(out)

    def _write_stopped(self, out: np.ndarray, where: dict[int, int] | None = None) -> None:
        """The stopped rows into ``out`` (``where``: batch row -> row of
        ``out``, those only; by default every row): a diverged one's status
        only, it keeps its row."""
        for r, row in self.frozen.items():
            i = r if where is None else where.get(r)
            if i is not None:
                out[i] = row
        for r in self.diverged:
            i = r if where is None else where.get(r)
            if i is not None:
                out[i, _S["status"]] = float(VehicleStatus.DIVERGED)

    def step_watched(self, nsub: int, every: int, rows: np.ndarray, out: np.ndarray) -> None:
        """``step(nsub)``, ``every`` frames at a time, with the states of the
        batch's ``rows`` after each piece ``c`` in ``out[c]`` (``out``: at
        least ``nsub // every`` blocks of ``(len(rows), width)`` holding those
        rows' last states: a diverged row keeps its own)."""
        for c in range(nsub // every):
            self.step(every)
            for g in self.groups:
                if not len(g.rows):
                    continue
                at = np.minimum(np.searchsorted(g.rows, rows), len(g.rows) - 1)
                mine = np.flatnonzero(g.rows[at] == rows)  # rows flying in this group
                if len(mine):
                    block = np.empty((len(mine), out.shape[2]))
                    self._write(g, block, at[mine])
                    out[c, mine] = block
            self._write_stopped(out[c], {r: i for i, r in enumerate(rows.tolist())})
