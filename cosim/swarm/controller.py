"""The swarm controller: telemetry in, DO_REPOSITION commands out.

Transport-free: ``on_message(message, link)`` takes what a ground station
receives (GLOBAL_POSITION_INT, ATTITUDE, COMMAND_ACK), ``step(tick)``
returns the commands to send, as ``Outbound`` (link, name, fields). The
in-process participant (``cosim.swarm.participant``) injects them into the
run's endpoint; ``cosim swarm --connect`` (``cosim.swarm.external``) sends
them over UDP. The same code, the same ticks: the tracks are identical.

Each controller step (every ``SwarmSpec.every_ticks``), per group: the
positions come from the latest GLOBAL_POSITION_INT of each vehicle (lat/lon
-> the scenario's local NED frame, exact WGS-84), the bank from the latest
ATTITUDE; the phase's end condition is checked (an end emits
``swarm_phase`` and the next phase starts at once); then every vehicle gets
``COMMAND_INT MAV_CMD_DO_REPOSITION`` = fly to the goal at the speed, then
loiter there (guidance's default bank-limited radius), at its layer
altitude (MSL), switching to GUIDED.

Speeds: the law's speed (with ``s_stall = stall_constant / sqrt(cos(roll))``,
the stall constant being the level-flight stall TAS at the vehicle's
current altitude from the model's own mass, wing area and CL_max) clipped
to ``[max(AIRSPEED_MIN, s_stall, stall_margin * s_stall(bank limit)),
AIRSPEED_MAX]`` (the envelope is the vehicle's own MAVLink parameters, from
the model's profile). Where the stall speed is above the envelope minimum,
it wins. The loiter floor ``stall_margin * s_stall(bank limit)`` is there
because every goal ends in a loiter flown at the bank limit: a speed only
just above the *current* (level) stall speed stalls the aircraft as soon
as it banks into that loiter (seen with uav700s at AIRSPEED_MIN = 26 m/s:
they stalled entering the loiter and, throttle idle, sank into the
ground). The float32 speed sent is rounded up, never below the floor.
After a group's last phase its vehicles keep their last goal (loitering
there).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import VehicleSpec
from cosim.mavlink import adapter as mav
from cosim.mavlink.endpoint import CONTROLLER_SYSID
from cosim.mavlink.params import ParamTable
from cosim.mavlink.personality import Personality
from cosim.mavlink.vehicle import MavVehicleSpec, mav_specs
from cosim.swarm import laws
from cosim.swarm.config import Phase, SwarmGroup, SwarmSpec
from cosim.vehicles import get_class

log = logging.getLogger(__name__)

CONTROLLER_COMPID = 190


class Outbound(NamedTuple):
    """A message to send on link ``link`` (0 for a single endpoint)."""

    link: int
    name: str
    fields: dict[str, Any]


@dataclass
class StallNumbers:
    mass_kg: float
    wing_area_m2: float
    clmax: float


_STALL_CACHE: dict[tuple[str, str], StallNumbers] = {}
#: a vehicle without a stall speed (it hovers or stands)
NO_STALL = StallNumbers(0.0, 1.0, 1.0)


def stall_numbers(spec: VehicleSpec) -> StallNumbers:
    """Mass and wing area as JSBSim reads them from the vehicle's model file,
    CL_max from its cosim profile (cached per model)."""
    key = (spec.model, spec.aircraft_dir)
    if key not in _STALL_CACHE:
        from cosim.analysis.flight import LB_TO_KG, SQFT_TO_M2
        from cosim.vehicles.jsb import ModelInfo, new_fdm

        fdm = new_fdm(ModelInfo(spec.model, spec.aircraft_dir, spec.model_source,
                                profile=spec.profile), 1 / 120)
        fdm["ic/h-sl-ft"] = 1000.0
        fdm.run_ic()
        _STALL_CACHE[key] = StallNumbers(fdm["inertia/weight-lbs"] * LB_TO_KG,
                                         fdm["metrics/Sw-sqft"] * SQFT_TO_M2,
                                         float(spec.profile["clmax"]))
    return _STALL_CACHE[key]


@dataclass
class GroupState:
    group: SwarmGroup
    idx: np.ndarray  # controller indices of the group's vehicles
    phase: int = 0
    start_tick: int | None = None  # None: not started (waiting for telemetry)
    done: bool = False
    #: one record per phase: start/end tick, reason, spread at the end (telemetry)
    records: list[dict[str, Any]] = field(default_factory=list)


class SwarmController:
    """See the module docstring. ``links``: the MAVLink identities per link (default:
    one link, ``mav_specs(vehicles, get_class)``: system id = row + 1)."""

    def __init__(self, spec: SwarmSpec, vehicles: Sequence[VehicleSpec], frame: LocalFrame,
                 physics_hz: float, links: Sequence[Sequence[MavVehicleSpec]] | None = None
                 ) -> None:
        self.spec = spec
        self.frame = frame
        self.physics_hz = float(physics_hz)
        if links is None:
            links = [mav_specs(vehicles, get_class)]
        by_row = {ms.row: (li, ms) for li, specs in enumerate(links) for ms in specs}
        self.rows = np.array(spec.rows, dtype=np.intp)
        n = len(self.rows)
        self.ids = [vehicles[r].id for r in self.rows.tolist()]
        self.index_of_row = {r: i for i, r in enumerate(self.rows.tolist())}
        self._key: dict[tuple[int, int], int] = {}
        self.address: list[tuple[int, int]] = []
        self.min_mps = np.empty(n)
        self.max_mps = np.empty(n)
        numbers = []
        bank_deg: list[float] = []
        for i, r in enumerate(self.rows.tolist()):
            li, ms = by_row[r]
            self._key[(li, ms.sysid)] = i
            self.address.append((li, ms.sysid))
            params = ParamTable((ms.personality or Personality()).param_defs, ms.params)
            lim = get_class(vehicles[r].vehicle_class).swarm_limits(vehicles[r], params)
            self.min_mps[i] = lim.min_mps
            self.max_mps[i] = lim.max_mps
            bank_deg.append(lim.bank_limit_deg)
            # a vehicle that can stop has no stall speed: a zero mass makes it 0
            numbers.append(stall_numbers(vehicles[r]) if lim.stalls else NO_STALL)
        self.mass_kg = np.array([s.mass_kg for s in numbers])
        self.wing_area_m2 = np.array([s.wing_area_m2 for s in numbers])
        self.clmax = np.array([s.clmax for s in numbers])
        self.lat_deg = np.full(n, np.nan)
        self.lon_deg = np.full(n, np.nan)
        self.alt_msl_m = np.full(n, np.nan)
        self.roll_rad = np.full(n, np.nan)
        self.layer_alt_msl_m = np.array([vehicles[r].alt_msl_m for r in self.rows.tolist()])
        #: the bank every loiter is flown at: each vehicle's ROLL_LIMIT_DEG, followed
        #: through the PARAM_VALUE a vehicle announces when it changes
        self.bank_limit_rad = np.radians(np.array(bank_deg, dtype=float))
        self.groups: list[GroupState] = []
        for g in spec.groups:
            idx = np.array([self.index_of_row[r] for r in g.rows], dtype=np.intp)
            if g.layer_spacing_m is not None:
                base = float(self.layer_alt_msl_m[idx].min())
                self.layer_alt_msl_m[idx] = base + np.arange(len(idx)) * g.layer_spacing_m
            self.groups.append(GroupState(g, idx))
        #: (kind, tick, fields) produced since the last ``drain_events``
        self.events: list[tuple[str, int, dict[str, Any]]] = []
        #: every command sent: tick, vehicle index, speed (float32 as sent), stall speed,
        #: roll (rad) and altitude (m MSL) of the telemetry it used
        self.sent: list[tuple[int, int, float, float, float, float]] = []
        self.acks: Counter[str] = Counter()
        self.stall_above_max = 0

    # -- input -------------------------------------------------------------
    def on_message(self, m: mav.Message, link: int = 0) -> None:
        """Take one received message (telemetry of any vehicle; others ignored)."""
        i = self._key.get((link, m.src_system))
        if i is None:
            return
        f = m.fields
        if m.name == "GLOBAL_POSITION_INT":
            self.lat_deg[i] = f["lat"] * 1e-7
            self.lon_deg[i] = f["lon"] * 1e-7
            self.alt_msl_m[i] = f["alt"] * 1e-3
        elif m.name == "ATTITUDE":
            self.roll_rad[i] = f["roll"]
        elif m.name == "PARAM_VALUE" and f.get("param_id") == "ROLL_LIMIT_DEG":
            # the bank its loiters are flown at changed (a schedule, a ground station)
            self.bank_limit_rad[i] = math.radians(float(f["param_value"]))
        elif m.name == "COMMAND_ACK" and f.get("target_system") == CONTROLLER_SYSID:
            res = int(f["result"])
            if res == mav.MAV_RESULT_ACCEPTED:
                self.acks["accepted"] += 1
            else:
                self.acks["refused"] += 1
                if self.acks["refused"] == 1:
                    log.warning("swarm: vehicle %s refused a command (result %d)",
                                self.ids[i], res)

    # -- state -------------------------------------------------------------
    def positions_ne_m(self, idx: np.ndarray | None = None) -> np.ndarray:
        """(k, 2) north/east metres of the latest telemetry."""
        sel = slice(None) if idx is None else idx
        n, e, _ = self.frame.geodetic_to_ned(self.lat_deg[sel], self.lon_deg[sel],
                                             self.alt_msl_m[sel])
        return np.stack([np.atleast_1d(n), np.atleast_1d(e)], axis=1)

    def positions_ned_m(self) -> np.ndarray:
        n, e, d = self.frame.geodetic_to_ned(self.lat_deg, self.lon_deg, self.alt_msl_m)
        return np.stack([n, e, d], axis=1)

    def level_stall_mps(self, idx: np.ndarray) -> np.ndarray:
        """The level-flight stall TAS at the current altitude (the stall constant)."""
        return laws.level_stall_constant_mps(self.mass_kg[idx], self.wing_area_m2[idx],
                                             self.clmax[idx], self.alt_msl_m[idx])

    def stall_mps(self, idx: np.ndarray, level_mps: np.ndarray | None = None) -> np.ndarray:
        """The stall TAS in the current bank at the current altitude."""
        k = self.level_stall_mps(idx) if level_mps is None else level_mps
        return laws.stall_speed_mps(k, self.roll_rad[idx])

    def speed_floor_mps(self, idx: np.ndarray, stall_mps: np.ndarray,
                        level_mps: np.ndarray) -> np.ndarray:
        """The lowest speed commanded: the current stall speed, or the loiter
        floor ``stall_margin * stall speed at the bank limit`` if higher
        (``level_mps``: ``level_stall_mps(idx)``)."""
        loiter = self.spec.stall_margin * laws.stall_speed_mps(level_mps,
                                                               self.bank_limit_rad[idx])
        return np.maximum(stall_mps, loiter)

    @property
    def finished(self) -> bool:
        return all(g.done for g in self.groups)

    # -- the step ----------------------------------------------------------
    def due(self, tick: int) -> bool:
        return tick % self.spec.every_ticks == 0

    def step(self, tick: int) -> list[Outbound]:
        """The commands for controller step ``tick`` (call it when ``due``)."""
        out: list[Outbound] = []
        for gs in self.groups:
            if gs.done:
                continue
            idx = gs.idx
            if np.isnan(self.lat_deg[idx]).any() or np.isnan(self.roll_rad[idx]).any():
                continue  # not every vehicle heard from yet
            p = self.positions_ne_m(idx)
            if gs.start_tick is None:
                self._start(gs, tick)
            while not gs.done:
                reason = self._ended(gs, p, tick)
                if reason is None:
                    break
                self._end(gs, tick, reason, p)
            if gs.done:
                continue
            out.extend(self._commands(gs, p, tick))
        return out

    def _phase(self, gs: GroupState) -> Phase:
        return gs.group.phases[gs.phase]

    def _start(self, gs: GroupState, tick: int) -> None:
        gs.start_tick = tick
        ph = self._phase(gs)
        gs.records.append({"phase": gs.phase, "behaviour": ph.behaviour,
                           "start_tick": tick, "start_s": tick / self.physics_hz})
        self.events.append(("swarm_phase", tick, {
            "group": gs.group.name, "behaviour": ph.behaviour, "phase": gs.phase,
            "state": "start", "vehicles": len(gs.idx)}))
        log.info("swarm %s: phase %d %s starts at %.1f s", gs.group.name, gs.phase,
                 ph.behaviour, tick / self.physics_hz)

    def _ended(self, gs: GroupState, p: np.ndarray, tick: int) -> str | None:
        ph = self._phase(gs)
        assert gs.start_tick is not None
        elapsed_s = (tick - gs.start_tick) / self.physics_hz
        d = laws.distances_to_centroid_m(p)
        if ph.behaviour == "rendezvous" and ph.radius_m is not None and d.max() <= ph.radius_m:
            return "converged"
        if ph.behaviour == "anti_rendezvous" and ph.radius_m is not None \
                and d.min() >= ph.radius_m:
            return "converged"
        if ph.behaviour == "flocking" and ph.duration_s is not None \
                and elapsed_s >= ph.duration_s - 1e-9:
            return "duration"
        if ph.timeout_s is not None and elapsed_s >= ph.timeout_s - 1e-9:
            return "timeout"
        return None

    def _end(self, gs: GroupState, tick: int, reason: str, p: np.ndarray | None) -> None:
        ph = self._phase(gs)
        rec = gs.records[-1]
        assert gs.start_tick is not None
        fields: dict[str, Any] = {"group": gs.group.name, "behaviour": ph.behaviour,
                                  "phase": gs.phase, "state": "end", "reason": reason,
                                  "duration_s": (tick - gs.start_tick) / self.physics_hz}
        if p is not None:
            d = laws.distances_to_centroid_m(p)
            fields.update(spread_max_m=float(d.max()), spread_min_m=float(d.min()))
        rec.update({k: v for k, v in fields.items() if k not in ("group", "state")},
                   end_tick=tick, end_s=tick / self.physics_hz)
        self.events.append(("swarm_phase", tick, fields))
        log.info("swarm %s: phase %d %s ends at %.1f s (%s)", gs.group.name, gs.phase,
                 ph.behaviour, tick / self.physics_hz, reason)
        if reason == "run_end" or gs.phase + 1 >= len(gs.group.phases):
            gs.done = True
            return
        gs.phase += 1
        self._start(gs, tick)

    def end_run(self, tick: int) -> None:
        """Close the phases still running (reason ``run_end``)."""
        for gs in self.groups:
            if not gs.done and gs.start_tick is not None:
                idx = gs.idx
                p = None if np.isnan(self.lat_deg[idx]).any() else self.positions_ne_m(idx)
                self._end(gs, tick, "run_end", p)

    def _commands(self, gs: GroupState, p: np.ndarray, tick: int) -> list[Outbound]:
        ph = self._phase(gs)
        idx = gs.idx
        level = self.level_stall_mps(idx)
        stall = self.stall_mps(idx, level)
        if ph.behaviour == "rendezvous":
            goal, speed = laws.rendezvous(p, ph.mu, ph.k_s, stall)
        elif ph.behaviour == "anti_rendezvous":
            goal, speed = laws.anti_rendezvous(p, ph.mu, ph.k_s, stall)
        else:
            assert ph.q_ne_m is not None
            goal, speed = laws.flocking(p, ph.mu, ph.k_s, ph.q_ne_m, stall)
        floor = self.speed_floor_mps(idx, stall, level)
        speed = laws.clip_speed_mps(speed, floor, self.min_mps[idx], self.max_mps[idx])
        over = floor > self.max_mps[idx]
        if over.any():
            self.stall_above_max += int(over.sum())
            log.warning("swarm %s: stall speed above AIRSPEED_MAX for %d vehicle(s); "
                        "commanding AIRSPEED_MAX", gs.group.name, int(over.sum()))
        speed32 = laws.float32_at_least(speed)
        alt = self.layer_alt_msl_m[idx]
        lat, lon, _ = self.frame.ned_to_geodetic(goal[:, 0], goal[:, 1],
                                                 -(alt - self.frame.alt_m))
        out = []
        for k, i in enumerate(idx.tolist()):
            link, sysid = self.address[i]
            out.append(Outbound(link, "COMMAND_INT", {
                "target_system": sysid, "target_component": mav.MAV_COMP_ID_AUTOPILOT1,
                "frame": mav.MAV_FRAME_GLOBAL_INT, "command": mav.MAV_CMD_DO_REPOSITION,
                "current": 0, "autocontinue": 0, "param1": float(speed32[k]),
                "param2": float(mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE), "param3": 0.0,
                "param4": 0.0, "x": int(round(float(lat[k]) * 1e7)),
                "y": int(round(float(lon[k]) * 1e7)), "z": float(np.float32(alt[k]))}))
            self.sent.append((tick, i, float(speed32[k]), float(stall[k]),
                              float(self.roll_rad[i]), float(self.alt_msl_m[i])))
        return out

    # -- summary -----------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """The controller's view (telemetry): phases per group, commands, ACKs."""
        return {
            "rate_hz": self.spec.rate_hz,
            "commands_sent": len(self.sent),
            "acks": dict(self.acks),
            "stall_above_airspeed_max": self.stall_above_max,
            "groups": {gs.group.name: {"vehicles": [self.ids[i] for i in gs.idx.tolist()],
                                       "phases": gs.records} for gs in self.groups},
        }

    def drain_events(self) -> list[tuple[str, int, dict[str, Any]]]:
        ev, self.events = self.events, []
        return ev


def to_message(o: Outbound) -> mav.Message:
    """An in-process message, exactly as the network would deliver it: every
    field is given (``Outbound`` carries them all), integers fit their wire
    types, and ``wire_values`` rounds the floats to float32 (``make_message``
    gives the same, at ~20x the cost of packing and parsing each one)."""
    return mav.Message(o.name, CONTROLLER_SYSID, CONTROLLER_COMPID,
                       mav.wire_values(o.name, dict(o.fields)))
