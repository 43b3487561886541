"""A vehicle rebuilt where it was: what the state array lacks for that, read
at every exchange, and the FDM built back from it instead of trimmed.

A pool that may have to rebuild its vehicles elsewhere (the ray backend's
agents, whose machine may be lost) gathers ``FIELDS`` beside the state
array (``Reader``): the body rates, the flight controls' commands and trims,
the fuel in the first two tanks and the integrators of cosim's autopilot
(read as the PID's output less its proportional part; JSBSim takes them
back through ``<pid>/initial-integrator-value``). The state array itself
gives the position, the attitude and the NED velocities.

``resume_spec`` turns a vehicle's last state row, these columns and the
last value of every setpoint channel into a ``VehicleSpec`` whose
``resume`` lists the JSBSim properties to start from; ``restore`` builds
the FDM from them (``Vehicle``, in place of the trim):

1. initial conditions: position, attitude, NED velocities, body rates;
2. the scenario's ``set:`` properties, the channels' last setpoints, then
   the controls as they were (an autopilot may have moved them since);
3. ``run_ic``, the engines started (which puts the throttle and mixture at
   full), the controls and integrators written again;
4. ``run_ic`` once more with JSBSim's trim flag set, which settles every
   actuator and filter of the flight controls on its input (the autopilot's
   rate-limited bank command on the bank it was flying); the controls and
   integrators written once more (that pass recomputed the autopilot's
   outputs and integrated one step), then the engines' steady state for
   that throttle and airspeed.

``NOT_RESTORED`` says what is not carried over. The same rebuild in the same
state gives the same states: it is deterministic, but no longer bit-exact
with a run that lost nothing.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import jsbsim
import numpy as np

from cosim.core.state import STATE_INDEX, StateField, VehicleSpec
from cosim.core.units import FT_TO_M
from cosim.errors import JSBSimError
from cosim.vehicles.jsb import has_property
from cosim.vehicles.registry import get_class

_get = jsbsim.FGPropertyNode.get_double_value

#: (property read, initial condition it is written back to): the body rates
RATES = (("velocities/p-rad_sec", "ic/p-rad_sec"), ("velocities/q-rad_sec", "ic/q-rad_sec"),
         ("velocities/r-rad_sec", "ic/r-rad_sec"))
#: written back as they were read (a model without one reads NaN, skipped)
CONTROLS = ("fcs/elevator-cmd-norm", "fcs/aileron-cmd-norm", "fcs/rudder-cmd-norm",
            "fcs/pitch-trim-cmd-norm", "fcs/roll-trim-cmd-norm", "fcs/yaw-trim-cmd-norm",
            "fcs/throttle-cmd-norm", "fcs/mixture-cmd-norm", "fcs/flap-cmd-norm",
            "propulsion/tank/contents-lbs", "propulsion/tank[1]/contents-lbs")
#: the PIDs of cosim's autopilot (aircraft/systems/cosim_autopilot.xml):
#: (PID, its input, its kp); none has a kd, so integrator = output - kp * input
AUTOPILOT_PIDS = (("cosim/ap/roll-pi", "cosim/ap/roll-error-deg", "cosim/ap/gain/roll-kp"),
                  ("cosim/ap/vs-pi-deg", "cosim/ap/vs-error-fps", "cosim/ap/gain/vs-kp"),
                  ("cosim/ap/theta-pi", "cosim/ap/theta-error-deg", "cosim/ap/gain/theta-kp"),
                  ("cosim/ap/speed-pi", "cosim/ap/speed-error-kt", "cosim/ap/gain/spd-kp"))
_INTEGRATOR = "/initial-integrator-value"
#: properties of the state itself (given back only as initial conditions)
_STATE_PROPS = ("position/", "attitude/", "velocities/", "ic/", "simulation/")
#: the columns a rebuildable pool adds to its state array, in this order
FIELDS: tuple[StateField, ...] = tuple(
    StateField(f"resume:{p}", None) for p in
    [p for p, _ in RATES] + list(CONTROLS) + [pid + _INTEGRATOR for pid, _, _ in AUTOPILOT_PIDS])

#: what a rebuilt JSBSim vehicle carries over, and what not (the run's event says both)
RESTORED = ("position", "attitude", "NED velocities", "body rates",
            "flight control commands and trims", "fuel in the first two tanks",
            "autopilot setpoints and integrators")
NOT_RESTORED = (
    "engine speed (rpm, spools): restarted at its steady state for the throttle and airspeed",
    "an actuator or filter still moving toward its input (the autopilot's bank command while "
    "it rolls into a turn): restarted on its input",
    "integrators of controllers other than cosim's autopilot (a quadrotor's): restarted at 0",
    "JSBSim's random stream (turbulence) and clock: restarted",
    "fuel beyond the first two tanks: full again",
    "vehicles of a batched class: all but position, heading and speed",
)


class Reader:
    """Reads what ``FIELDS`` are made of from one FDM (NaN where its model
    lacks a property); ``columns`` makes a block of reads the columns."""

    __slots__ = ("_nodes",)

    def __init__(self, fdm: jsbsim.FGFDMExec) -> None:
        pm = fdm.get_property_manager()
        absent: jsbsim.FGPropertyNode | None = None
        names = [p for p, _ in RATES] + list(CONTROLS)
        names += [n for k in range(3) for n in (pid[k] for pid in AUTOPILOT_PIDS)]
        self._nodes: list[jsbsim.FGPropertyNode] = []
        for name in names:
            node = pm.get_node(name) if has_property(fdm, name) else None
            if node is None:  # reads NaN for whatever this model lacks
                if absent is None:
                    absent = pm.get_node("cosim/resume-absent", True)
                    assert absent is not None
                    absent.set_double_value(math.nan)
                node = absent
            self._nodes.append(node)

    def read(self) -> list[float]:
        return list(map(_get, self._nodes))


def columns(reads: np.ndarray) -> np.ndarray:
    """``FIELDS`` from a block of ``Reader.read`` rows: the rates and controls
    as read, each autopilot integrator its PID's output less kp * input."""
    m = len(AUTOPILOT_PIDS)
    k = len(RATES) + len(CONTROLS)
    out, inp, kp = reads[:, k:k + m], reads[:, k + m:k + 2 * m], reads[:, k + 2 * m:]
    return np.concatenate([reads[:, :k], out - kp * inp], axis=1)


def resume_spec(spec: VehicleSpec, row: np.ndarray, extra: np.ndarray,
                channels: Sequence[str] = (), latched: np.ndarray | None = None
                ) -> VehicleSpec:
    """``spec`` started where its last state ``row`` (and ``extra``, its
    ``FIELDS`` columns) left it, with ``latched``, the last value sent on
    each of ``channels`` (NaN: none). A JSBSim vehicle whose columns were
    gathered is restored (``restore``); any other starts from its position,
    heading and speed (trimmed, if its spec says so)."""
    s = STATE_INDEX
    moved = dataclasses.replace(spec, lat_deg=float(row[s["lat_deg"]]),
                                lon_deg=float(row[s["lon_deg"]]),
                                alt_msl_m=float(row[s["alt_msl_m"]]),
                                heading_deg=float(row[s["yaw_deg"]]) % 360.0,
                                airspeed_mps=float(row[s["airspeed_mps"]]))
    if get_class(spec.vehicle_class).model_kind != "jsbsim" or \
            not np.isfinite(extra[:len(RATES)]).all():
        return moved
    ft = 1.0 / FT_TO_M
    pairs: list[tuple[str, float]] = [
        ("ic/lat-geod-deg", row[s["lat_deg"]]), ("ic/long-gc-deg", row[s["lon_deg"]]),
        ("ic/terrain-elevation-ft", spec.terrain_alt_m * ft),
        ("ic/h-sl-ft", row[s["alt_msl_m"]] * ft),
        ("ic/phi-deg", row[s["roll_deg"]]), ("ic/theta-deg", row[s["pitch_deg"]]),
        ("ic/psi-true-deg", row[s["yaw_deg"]]),
        ("ic/vn-fps", row[s["vn_mps"]] * ft), ("ic/ve-fps", row[s["ve_mps"]] * ft),
        ("ic/vd-fps", row[s["vd_mps"]] * ft)]
    pairs += [(ic, v) for (_, ic), v in zip(RATES, extra[:len(RATES)])]
    if latched is not None:  # channels first: the controls as they were win
        pairs += [(c, v) for c, v in zip(channels, latched) if not math.isnan(v)]
    named = [f.name.removeprefix("resume:") for f in FIELDS[len(RATES):]]
    pairs += [(p, v) for p, v in zip(named, extra[len(RATES):]) if not math.isnan(v)]
    return dataclasses.replace(moved, resume=tuple((p, float(v)) for p, v in pairs))


def restore(fdm: jsbsim.FGFDMExec, spec: VehicleSpec) -> None:
    """Build ``fdm`` (its model loaded) in the state ``spec.resume`` lists
    (``resume_spec``), in place of initial conditions and a trim."""
    ic = [(p, v) for p, v in spec.resume if p.startswith("ic/")]
    integrators = [(p, v) for p, v in spec.resume if p.endswith(_INTEGRATOR)]
    # not the state's own properties: a value that once put the vehicle somewhere
    # would put it back there; nor a channel of another class (not this model's)
    props = [(p, v) for p, v in (*spec.initial_props, *spec.resume)
             if not p.startswith(_STATE_PROPS) and not p.endswith(_INTEGRATOR)
             and has_property(fdm, p)]

    def write(pairs: list[tuple[str, float]]) -> None:
        for p, v in pairs:
            fdm[p] = v

    fdm["simulation/randomseed"] = float(spec.random_seed)
    write(ic)  # latitude and longitude first, as resume_spec lists them
    write(props)
    if not fdm.run_ic():
        raise JSBSimError(f"vehicle {spec.id!r}: JSBSim run_ic() failed", spec.id)
    fdm["propulsion/set-running"] = -1  # throttle and mixture to full: written back next
    write(props)
    write(integrators)
    fdm.set_trim_status(True)  # actuators and filters follow their inputs in this pass
    try:
        ok = fdm.run_ic()
    finally:
        fdm.set_trim_status(False)
    if not ok:
        raise JSBSimError(f"vehicle {spec.id!r}: JSBSim run_ic() failed", spec.id)
    write(props)  # the autopilot's outputs as it had last set them, not as that pass did
    write(integrators)
    fdm.get_propulsion().get_steady_state()
