"""Fixed-wing guidance: commands -> autopilot setpoints, path following.

Runs in the driver at the exchange rate, vectorised over vehicles. It sees
vehicles only through the state array and acts only by writing the cosim
autopilot's setpoint properties (``AP_CHANNELS``) into the pool's setpoint
array; the loops themselves run inside JSBSim.

Lateral guidance follows legs and loiter circles with a carrot point
``L1`` metres ahead along the path (pure pursuit of the L1 point), with
``L1 = max(1.5 R_turn, 150 m)`` and ``R_turn = v^2 / (g tan(bank limit))``,
so the commanded heading changes no faster than a bank-limited turn can
follow. Headings are bearings in each vehicle's own local frame.
A fixed-wing cannot stop: a goto ends in a loiter around the target, and
waypoints end in a loiter around the last one.

``land`` (alone: straight ahead; with ``goto`` or ``waypoints``: at the last
point, after the others): the last leg is flown on, over the point, on a
glide path of ``GLIDE_DEG`` to the ground at the point (its altitude hold
in AGL mode follows the along-track distance each exchange, at the speed
commanded), with the autopilot's ``cosim/ap/landing`` set so that a gentle
touchdown (skids or wheels in contact: ``gear_force_lbs``) is a
landing (``cosim.vehicles.jsbsim_model``); on the ground the engine idles,
the autopilot holds the ground pitch (``cosim/ap/landing`` 2,
``cosim/ap/ground-pitch-deg``: nose wheel or skids down, no lift to bounce
on), brakes where it has them, and the aircraft rolls or slides to a stop
(``touchdown`` and ``landed`` events). It does not take off again: a later
command is ignored with a ``command_ignored`` event.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cosim.core.geo import LocalFrame, bearing_deg
from cosim.core.state import STATE_INDEX
from cosim.core.units import FT_TO_M, G_MPS2, KT_TO_MPS
from cosim.guidance.commands import (
    DEFAULT_BANK_LIMIT_DEG,
    Command,
    Point,
    min_turn_radius_m,
    waypoint_accept_radius_m,
)
from cosim.vehicles.base import GuidanceEvent

#: the autopilot setpoints guidance writes (see aircraft/systems/cosim_autopilot.xml)
AP_CHANNELS: tuple[str, ...] = (
    "cosim/ap/engage", "cosim/ap/heading-hold", "cosim/ap/heading-cmd-deg",
    "cosim/ap/bank-limit-deg", "cosim/ap/alt-hold", "cosim/ap/alt-cmd-ft", "cosim/ap/alt-mode",
    "cosim/ap/speed-hold", "cosim/ap/speed-cmd-kt", "cosim/ap/throttle-bias",
    "cosim/ap/stall-protect", "fcs/throttle-cmd-norm", "cosim/ap/landing",
    "fcs/left-brake-cmd-norm", "fcs/right-brake-cmd-norm",
)
_NONE, _LEG, _LOITER = 0, 1, 2
#: the glide path of a landing (degrees below the horizon)
GLIDE_DEG = 3.0
#: how far (seconds of flight) before the landing point the commanded glide
#: path meets the ground: the altitude hold lags the path it follows by about
#: this much, so the touchdown falls near the point
GLIDE_LEAD_S = 8.0
#: the wheel brakes on the ground after a landing (0..1; skids have none)
ROLLOUT_BRAKE = 0.5
#: a landing's phases: none, on the glide path, on the ground sliding, stopped
_NOT_LANDING, _APPROACH, _ROLLOUT, _LANDED = 0, 1, 2, 3
_S = STATE_INDEX
_M_TO_FT = 1.0 / FT_TO_M


class FixedWingGuidance:
    """Guidance of a run's fixed-wing vehicles (arrays over every state row;
    only its class's rows are ever commanded)."""

    def __init__(self, n: int, frame: LocalFrame, start_ne: np.ndarray,
                 channel_index: dict[str, int], ne_columns: tuple[int, int] | None = None
                 ) -> None:
        self.n = n
        #: state columns of north and east in the scenario frame, where the
        #: model flies in that flat frame (the batched tier): positions are
        #: read, not converted, and headings are bearings in the scenario frame
        self.ne_cols = np.array(ne_columns, dtype=np.intp) if ne_columns is not None \
            else None
        #: positions of the rows a command is being applied to (``command``)
        self._here: dict[int, np.ndarray] = {}
        self.frame = frame
        self.ground_alt_m = frame.alt_m
        self.start_ne = np.asarray(start_ne, dtype=np.float64).reshape(n, 2)
        self.ch = channel_index
        self.engaged = np.zeros(n, dtype=bool)
        self.nav = np.zeros(n, dtype=np.int8)
        self.a = np.zeros((n, 2))  # leg start (north, east), scenario frame
        self.b = np.zeros((n, 2))  # leg end / loiter centre
        self.radius = np.zeros(n)  # loiter radius
        self.cw = np.ones(n, dtype=bool)
        self.end_radius = np.full(n, np.nan)  # loiter radius at the end of a goto/waypoints
        self.bank_limit = np.full(n, DEFAULT_BANK_LIMIT_DEG)
        self.speed_cmd = np.full(n, np.nan)  # commanded TAS (m/s), NaN: none
        self.queue: dict[int, list[tuple[float, float, Point]]] = {}
        self.wp_index = np.zeros(n, dtype=np.int32)
        self.wp_total = np.zeros(n, dtype=np.int32)
        self.kind = [""] * n  # "goto" / "waypoints" / "loiter"
        self.labels = [""] * n
        self.landing = np.zeros(n, dtype=np.int8)  # the phase (``_APPROACH``, ...)
        self.land_at_end = np.zeros(n, dtype=bool)  # land at the route's last point
        self.fly_on = np.zeros(n, dtype=bool)  # a goto flown on past its point (no loiter)
        self.land_point = np.zeros((n, 2))
        self.land_alt = np.zeros(n)  # the height (AGL) it flies until the glide path
        #: events of commands refused, for the next ``update``
        self.pending: list[GuidanceEvent] = []

    # -- commands --------------------------------------------------------
    def _set(self, sp: np.ndarray, rows: Any, name: str, value: Any) -> None:
        sp[rows, self.ch[name]] = value

    def resolve(self, p: Point, i: int) -> tuple[float, float]:
        """A point's (north, east) metres in the scenario frame for vehicle i."""
        if p.frame == "geodetic":
            n, e, _ = self.frame.geodetic_to_ned(p.a, p.b, self.ground_alt_m)
            return float(n), float(e)
        if p.frame == "start":
            return float(self.start_ne[i, 0] + p.a), float(self.start_ne[i, 1] + p.b)
        return p.a, p.b

    def _alt_speed(self, sp: np.ndarray, i: int, alt: float | None, agl: bool,
                   spd: float | None, states: np.ndarray) -> None:
        if alt is not None:
            self._set(sp, i, "cosim/ap/alt-hold", 1.0)
            self._set(sp, i, "cosim/ap/alt-mode", 1.0 if agl else 0.0)
            self._set(sp, i, "cosim/ap/alt-cmd-ft", alt * _M_TO_FT)
        if spd is not None:
            self._set(sp, i, "cosim/ap/speed-hold", 1.0)
            self._set(sp, i, "cosim/ap/speed-cmd-kt", spd / KT_TO_MPS)
            self._set(sp, i, "cosim/ap/throttle-bias", states[i, _S["throttle"]])
            self.speed_cmd[i] = spd

    def turn_radius(self, i: int | np.ndarray, v_mps: Any) -> Any:
        return np.asarray(v_mps) ** 2 / (G_MPS2 * np.tan(np.radians(self.bank_limit[i])))

    def command(self, rows: list[int], cmd: Command, states: np.ndarray, sp: np.ndarray
                ) -> None:
        """Apply ``cmd`` to vehicles ``rows`` (indices) given the current states."""
        if cmd.nav is not None and len(rows) > 1:  # every position in one conversion
            pos = self.position_ne(states, np.asarray(rows))
            self._here = {i: pos[k] for k, i in enumerate(rows)}
        try:
            self._command(rows, cmd, states, sp)
        finally:
            self._here = {}

    def _command(self, rows: list[int], cmd: Command, states: np.ndarray, sp: np.ndarray
                 ) -> None:
        for i in rows:
            s = states[i]
            if self.landing[i] in (_ROLLOUT, _LANDED):  # on the ground: it stays there
                self.pending.append(GuidanceEvent("command_ignored", i, {
                    "command": cmd.label(),
                    "reason": "a fixed-wing does not take off again after a landing"}))
                continue
            if not self.engaged[i]:  # engage, holding the current state on every axis
                self.engaged[i] = True
                self._set(sp, i, "cosim/ap/engage", 1.0)
                self._set(sp, i, "cosim/ap/heading-hold", 1.0)
                self._set(sp, i, "cosim/ap/heading-cmd-deg", s[_S["yaw_deg"]])
                self._alt_speed(sp, i, s[_S["alt_msl_m"]], False,
                                None if cmd.throttle is not None else s[_S["airspeed_mps"]],
                                states)
            if cmd.bank_limit_deg is not None:
                self.bank_limit[i] = cmd.bank_limit_deg
                self._set(sp, i, "cosim/ap/bank-limit-deg", cmd.bank_limit_deg)
            if cmd.stall_protection is not None:
                self._set(sp, i, "cosim/ap/stall-protect", 1.0 if cmd.stall_protection else 0.0)
            if cmd.throttle is not None:
                self._set(sp, i, "cosim/ap/speed-hold", 0.0)
                self._set(sp, i, "fcs/throttle-cmd-norm", cmd.throttle)
                self.speed_cmd[i] = np.nan
            self._alt_speed(sp, i, cmd.alt_m, cmd.alt_agl, cmd.airspeed_mps, states)
            if cmd.heading_deg is not None:
                self._stop_nav(i)
                self._set(sp, i, "cosim/ap/heading-cmd-deg", cmd.heading_deg)
            if cmd.nav is not None or cmd.heading_deg is not None:
                self._cancel_landing(i, sp)
            if cmd.nav is not None:
                self.land_at_end[i] = cmd.land
                self._start_nav(i, cmd, states, sp)
            elif cmd.land:
                self._land_ahead(i, states, sp)
            self.labels[i] = self._label(i, cmd)

    def _label(self, i: int, cmd: Command) -> str:
        if cmd.nav is None and cmd.heading_deg is None and self.nav[i] != _NONE:
            return self.labels[i]  # settings only: the navigation goes on
        return cmd.label()

    def _cancel_landing(self, i: int, sp: np.ndarray) -> None:
        """A new route or heading during the approach: no landing."""
        if self.landing[i] == _APPROACH:
            self.landing[i] = _NOT_LANDING
            self._set(sp, i, "cosim/ap/landing", 0.0)
        self.land_at_end[i] = False

    def _land_ahead(self, i: int, states: np.ndarray, sp: np.ndarray) -> None:
        """``land`` alone: at the point where the glide path from here meets
        the ground, straight ahead."""
        here = self.position_ne(states, np.array([i]))[0]
        psi = math.radians(float(states[i, _S["yaw_deg"]]))
        dist = max(float(states[i, _S["alt_agl_m"]]), 0.0) / math.tan(math.radians(GLIDE_DEG))
        point = here + dist * np.array([math.cos(psi), math.sin(psi)])
        self.kind[i] = "land"
        self._start_landing(i, here, point, sp, float(states[i, _S["alt_agl_m"]]))

    def _start_landing(self, i: int, start: np.ndarray, point: np.ndarray,
                       sp: np.ndarray, agl: float) -> None:
        """Fly from ``start`` over ``point`` and on, at height ``agl`` until
        the glide path, then down it."""
        self.land_alt[i] = agl
        d = point - start
        u = d / max(float(np.hypot(*d)), 1e-6)
        self.queue.pop(i, None)
        self.nav[i] = _LEG
        self.a[i] = start
        self.b[i] = point + 5000.0 * u  # past the point: straight on after touchdown
        self.land_point[i] = point
        self.landing[i] = _APPROACH
        self.land_at_end[i] = False
        self._set(sp, i, "cosim/ap/landing", 1.0)
        self._set(sp, i, "cosim/ap/alt-hold", 1.0)
        self._set(sp, i, "cosim/ap/alt-mode", 1.0)
        self.labels[i] = "land"

    def _landing_update(self, states: np.ndarray, sp: np.ndarray,
                        events: list[GuidanceEvent]) -> None:
        """The glide path of the vehicles landing; touchdown and stop."""
        idx = np.flatnonzero(self.landing == _APPROACH)
        if idx.size:
            pos = self.position_ne(states, idx)
            for k, i in enumerate(idx.tolist()):
                u = self.b[i] - self.a[i]
                u = u / max(float(np.hypot(*u)), 1e-6)
                to_go = float(np.dot(self.land_point[i] - pos[k], u))
                if states[i, _S["gear_force_lbs"]] != 0.0:  # skids or wheels down: landed
                    self.landing[i] = _ROLLOUT
                    self.nav[i] = _NONE
                    self._set(sp, i, "cosim/ap/speed-hold", 0.0)
                    self._set(sp, i, "cosim/ap/alt-hold", 0.0)
                    self._set(sp, i, "cosim/ap/landing", 2.0)  # holds the ground pitch
                    self._set(sp, i, "cosim/ap/heading-hold", 0.0)  # wings level
                    self._set(sp, i, "fcs/throttle-cmd-norm", 0.0)
                    for side in ("left", "right"):  # wheel brakes, where it has them
                        self._set(sp, i, f"fcs/{side}-brake-cmd-norm", ROLLOUT_BRAKE)
                    self.speed_cmd[i] = np.nan
                    events.append(GuidanceEvent("touchdown", i, {
                        "distance_m": -to_go,
                        "sink_mps": float(states[i, _S["vd_mps"]])}))
                    self.labels[i] = "touchdown"
                    continue
                lead = GLIDE_LEAD_S * float(states[i, _S["airspeed_mps"]])
                glide = min(max(to_go - lead, -200.0) * math.tan(math.radians(GLIDE_DEG)),
                            float(self.land_alt[i]))
                self._set(sp, i, "cosim/ap/alt-cmd-ft", glide * _M_TO_FT)
        for i in np.flatnonzero(self.landing == _ROLLOUT).tolist():
            if math.hypot(states[i, _S["vn_mps"]], states[i, _S["ve_mps"]]) < 0.5:
                self.landing[i] = _LANDED
                self.labels[i] = "landed"
                events.append(GuidanceEvent("landed", i, {}))

    def _stop_nav(self, i: int) -> None:
        self.nav[i] = _NONE
        self.queue.pop(i, None)
        self.kind[i] = ""

    def _speed_for_radius(self, i: int, states: np.ndarray) -> float:
        v = self.speed_cmd[i]
        return float(v) if v == v else float(states[i, _S["airspeed_mps"]])

    def _default_radius(self, i: int, states: np.ndarray) -> float:
        v = self._speed_for_radius(i, states)
        return max(1.5 * min_turn_radius_m(v, float(self.bank_limit[i])), 150.0)

    def _start_nav(self, i: int, cmd: Command, states: np.ndarray, sp: np.ndarray) -> None:
        here = self._here[i] if i in self._here else self.position_ne(states, np.array([i]))[0]
        self.kind[i] = cmd.nav or ""
        self.cw[i] = cmd.loiter_cw
        if cmd.nav == "loiter":
            centre = here if cmd.loiter_here or not cmd.points else np.array(
                self.resolve(cmd.points[0], i))
            self._begin_loiter(i, centre, cmd.loiter_radius_m or self._default_radius(i, states))
            self.queue.pop(i, None)
            return
        pts = [(*self.resolve(p, i), p) for p in cmd.points]
        self.end_radius[i] = cmd.loiter_radius_m if cmd.loiter_radius_m else np.nan
        self.wp_total[i] = len(pts)
        self.wp_index[i] = 0
        self.queue[i] = pts
        if cmd.leg_from is not None:  # the track from there (a mission's previous waypoint)
            here = np.array(self.resolve(cmd.leg_from, i))
        self.fly_on[i] = cmd.leg_continue and cmd.nav == "goto"
        self._begin_leg(i, here, states, sp)

    def _begin_leg(self, i: int, start: np.ndarray, states: np.ndarray, sp: np.ndarray) -> None:
        n, e, p = self.queue[i][0]
        self.nav[i] = _LEG
        self.a[i] = start
        self.b[i] = (n, e)
        if self.kind[i] == "waypoints":
            self._alt_speed(sp, i, p.alt_m, p.alt_agl, p.airspeed_mps, states)

    def _begin_loiter(self, i: int, centre: np.ndarray, radius: float) -> None:
        self.nav[i] = _LOITER
        self.b[i] = centre
        self.radius[i] = radius

    # -- every exchange --------------------------------------------------
    def position_ne(self, states: np.ndarray, idx: np.ndarray) -> np.ndarray:
        if self.ne_cols is not None:
            return states[np.ix_(np.atleast_1d(idx), self.ne_cols)]
        n, e, _ = self.frame.geodetic_to_ned(states[idx, _S["lat_deg"]], states[idx, _S["lon_deg"]],
                                             states[idx, _S["alt_msl_m"]])
        return np.stack([np.atleast_1d(n), np.atleast_1d(e)], axis=1)

    def update(self, states: np.ndarray, sp: np.ndarray) -> list[GuidanceEvent]:
        """Advance navigation for every guided vehicle; write heading setpoints."""
        events, self.pending = self.pending, []
        if (self.landing != _NOT_LANDING).any():
            self._landing_update(states, sp, events)
        idx = np.flatnonzero(self.nav != _NONE)
        if idx.size == 0:
            return events
        pos = self.position_ne(states, idx)
        v = np.maximum(states[idx, _S["airspeed_mps"]], 1.0)
        l1 = np.maximum(1.5 * self.turn_radius(idx, v), 150.0)
        # transitions first (they may change modes), then carrots
        for k in np.flatnonzero(self.nav[idx] == _LEG).tolist():
            i = int(idx[k])
            if self.nav[i] == _LEG:  # (an earlier transition may have changed it: no)
                self._leg_transition(i, pos[k], float(l1[k]), float(v[k]), states, sp, events)
        carrot = np.empty_like(pos)
        leg = self.nav[idx] == _LEG
        if leg.any():
            j = idx[leg]
            a, b, p = self.a[j], self.b[j], pos[leg]
            d = b - a
            length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-6)
            u = d / length[:, None]
            r = p - a
            along = r[:, 0] * u[:, 0] + r[:, 1] * u[:, 1]
            cross = u[:, 0] * r[:, 1] - u[:, 1] * r[:, 0]
            ahead = np.sqrt(np.maximum(l1[leg] ** 2 - cross ** 2, 0.0))
            carrot[leg] = a + u * (along + ahead)[:, None]
        loi = self.nav[idx] == _LOITER
        if loi.any():
            j = idx[loi]
            c, rad, p = self.b[j], self.radius[j], pos[loi]
            rel = p - c
            theta = np.arctan2(rel[:, 1], rel[:, 0])
            sign = np.where(self.cw[j], 1.0, -1.0)  # cw: bearing from centre increases
            step = np.minimum(l1[loi] / rad, math.pi / 2)
            ang = theta + sign * step
            carrot[loi] = c + rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        if self.ne_cols is not None:  # the scenario frame's bearing
            d = carrot - pos
            sp[idx, self.ch["cosim/ap/heading-cmd-deg"]] = np.degrees(
                np.arctan2(d[:, 1], d[:, 0])) % 360.0
            return events
        alt = states[idx, _S["alt_msl_m"]]
        clat, clon, _ = self.frame.ned_to_geodetic(carrot[:, 0], carrot[:, 1],
                                                   -(alt - self.ground_alt_m))
        hdg = bearing_deg(states[idx, _S["lat_deg"]], states[idx, _S["lon_deg"]], alt,
                          clat, clon, alt)
        sp[idx, self.ch["cosim/ap/heading-cmd-deg"]] = hdg
        return events

    def _leg_transition(self, i: int, p: np.ndarray, l1: float, v: float, states: np.ndarray,
                        sp: np.ndarray, events: list[GuidanceEvent]) -> None:
        if self.landing[i] == _APPROACH:
            return  # straight on, over the landing point
        a, b = self.a[i], self.b[i]
        dist = float(np.hypot(*(b - p)))
        d = b - a
        length = float(np.hypot(*d))
        along = float(np.dot(p - a, d / length)) if length > 1e-6 else length
        final = len(self.queue.get(i, ())) <= 1
        if final and self.land_at_end[i]:
            self._start_landing(i, a.copy(), b.copy(), sp, float(states[i, _S["alt_agl_m"]]))
            return
        if final and self.fly_on[i]:
            return  # on along the leg until the next command (a mission's next waypoint)
        if final:
            radius = self.end_radius[i]
            if radius != radius:  # NaN: default
                radius = self._default_radius(i, states)
            if dist <= max(radius, l1):
                events.append(GuidanceEvent("goal_reached", i, {
                    "command": self.kind[i], "north_m": float(b[0]), "east_m": float(b[1]),
                    "distance_m": dist, "loiter_radius_m": float(radius)}))
                self.queue.pop(i, None)
                self._begin_loiter(i, b.copy(), float(radius))
                self.labels[i] = f"loiter ({self.kind[i]} reached)"
            return
        accept = waypoint_accept_radius_m(v, float(self.bank_limit[i]))
        if dist <= accept or along >= length:
            n_done = int(self.wp_index[i]) + 1
            events.append(GuidanceEvent("waypoint_reached", i, {
                "index": n_done - 1, "of": int(self.wp_total[i]), "distance_m": dist}))
            self.queue[i].pop(0)
            self.wp_index[i] = n_done
            self.labels[i] = f"waypoints {n_done + 1}/{int(self.wp_total[i])}"
            self._begin_leg(i, b.copy(), states, sp)
