"""The quadrotor's guidance: commands to the setpoints of its controller.

The controller itself (position -> velocity -> attitude -> body rates, and
altitude -> climb rate -> collective) is a JSBSim system in the model
(``aircraft/F450/FlightControl.xml``) and runs at the physics rate; this
part only chooses what it holds, once per exchange:

- ``goto``: hold the point (the controller flies there at the speed limit,
  ``airspeed_*``, default 5 m/s, and stops on it); ``goal_reached`` once
  within ``ARRIVE_M`` and slower than 0.3 m/s;
- ``waypoints``: each point in turn (``waypoint_reached`` within
  ``PASS_M``), holding the last; with ``land: true``, landing on it;
- ``loiter``: hold the centre (default: where it is); with ``radius_m``,
  orbit it (clockwise unless ``direction: ccw``) at the speed limit, holding
  a point a little ahead on the circle each exchange; ``heading_deg``: turn
  to that heading where it is;
- ``velocity``: fly that ground velocity (north, east);
- altitudes (``alt_*``) and ``takeoff_agl_m``: climb or descend to it (3 m/s
  up, 1.5 m/s down); a take-off starts the motors;
- ``land``: descend where it is (or at the last point) at 1.5 m/s; on the
  ground the motors stop (``landed``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX
from cosim.guidance.commands import Command, Point
from cosim.vehicles.base import GuidanceEvent

_S = STATE_INDEX
ENGAGE, POS_HOLD = "cosim/quad/engage", "cosim/quad/pos-hold"
LAT, LON = "cosim/quad/lat-cmd-rad", "cosim/quad/lon-cmd-rad"
VN, VE = "cosim/quad/vn-cmd-mps", "cosim/quad/ve-cmd-mps"
SPEED, ALT = "cosim/quad/speed-max-mps", "cosim/quad/alt-cmd-m"
YAW = "cosim/quad/yaw-cmd-rad"
CHANNELS = (ENGAGE, POS_HOLD, LAT, LON, VN, VE, SPEED, ALT, YAW)
ARRIVE_M = 1.0
PASS_M = 2.0
DEFAULT_SPEED_MPS = 5.0
#: how far below the ground a landing aims (the controller sinks at its limit)
LAND_BELOW_M = 5.0


class QuadGuidance:
    """See the module docstring."""

    def __init__(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                 channel_index: Mapping[str, int]) -> None:
        n = len(start_ne)
        self.frame, self.start_ne = frame, start_ne
        self.ch = {c: channel_index[c] for c in CHANNELS}
        self.rows = list(rows)
        self.labels = [""] * n
        self.route: dict[int, list[tuple[float, float, float | None]]] = {}
        self.wp: dict[int, int] = {}
        self.landing: set[int] = set()
        self.land_at_end: set[int] = set()
        self.goal: dict[int, tuple[float, float]] = {}
        #: orbits: centre (north, east) in the frame, radius, clockwise
        self.orbit: dict[int, tuple[float, float, float, bool]] = {}
        self.speed: dict[int, float] = {}
        self.pending: list[GuidanceEvent] = []

    def _set(self, sp: np.ndarray, i: int, name: str, value: float) -> None:
        sp[i, self.ch[name]] = value

    def _latlon(self, p: Point, i: int) -> tuple[float, float]:
        if p.frame == "geodetic":
            return p.a, p.b
        n, e = (p.a, p.b) if p.frame == "local" else (self.start_ne[i, 0] + p.a,
                                                       self.start_ne[i, 1] + p.b)
        lat, lon = self.frame.place(n, e, self.frame.alt_m)
        return float(lat), float(lon)

    def _alt_of(self, p_alt: float | None, agl: bool, states: np.ndarray, i: int) -> float | None:
        if p_alt is None:
            return None
        ground = float(states[i, _S["alt_msl_m"]] - states[i, _S["alt_agl_m"]])
        return p_alt + ground if agl else p_alt

    def _hold(self, sp: np.ndarray, i: int, lat: float, lon: float) -> None:
        self._set(sp, i, POS_HOLD, 1.0)
        self._set(sp, i, LAT, math.radians(lat))
        self._set(sp, i, LON, math.radians(lon))

    def _here(self, states: np.ndarray, i: int) -> tuple[float, float]:
        return float(states[i, _S["lat_deg"]]), float(states[i, _S["lon_deg"]])

    def command(self, rows: list[int], cmd: Command, states: np.ndarray,
                sp: np.ndarray) -> None:
        for i in rows:
            ground = float(states[i, _S["alt_msl_m"]] - states[i, _S["alt_agl_m"]])
            if cmd.airspeed_mps is not None:
                self._set(sp, i, SPEED, cmd.airspeed_mps)
                self.speed[i] = cmd.airspeed_mps
            if cmd.nav is not None or cmd.velocity_ne is not None or cmd.land \
                    or cmd.heading_deg is not None:
                self.orbit.pop(i, None)
            alt = self._alt_of(cmd.alt_m, cmd.alt_agl, states, i)
            if cmd.takeoff_agl_m is not None:
                alt = ground + cmd.takeoff_agl_m
                self.landing.discard(i)
                self._set(sp, i, ENGAGE, 1.0)
                self._hold(sp, i, *self._here(states, i))
                self.labels[i] = f"takeoff {cmd.takeoff_agl_m:g} m"
            if alt is not None:
                self._set(sp, i, ALT, alt)
            if cmd.heading_deg is not None:
                self._set(sp, i, YAW, math.radians(cmd.heading_deg))
                self.route.pop(i, None)
                self._hold(sp, i, *self._here(states, i))
                self.labels[i] = f"heading {cmd.heading_deg:g}"
            if cmd.velocity_ne is not None:
                self.route.pop(i, None)
                self._set(sp, i, POS_HOLD, 0.0)
                self._set(sp, i, VN, cmd.velocity_ne[0])
                self._set(sp, i, VE, cmd.velocity_ne[1])
                self.labels[i] = "velocity {:g} {:g}".format(*cmd.velocity_ne)
            if cmd.nav == "loiter":
                self.route.pop(i, None)
                where = self._latlon(cmd.points[0], i) if cmd.points else self._here(states, i)
                self._hold(sp, i, *where)
                self.labels[i] = "hold"
                if cmd.loiter_radius_m:
                    n, e, _ = self.frame.geodetic_to_ned([where[0]], [where[1]],
                                                         [self.frame.alt_m])
                    self.orbit[i] = (float(n[0]), float(e[0]), cmd.loiter_radius_m,
                                     cmd.loiter_cw)
                    self.labels[i] = f"orbit {cmd.loiter_radius_m:g} m"
            elif cmd.nav in ("goto", "waypoints"):
                self.route[i] = [(*self._latlon(p, i), self._alt_of(p.alt_m, p.alt_agl, states, i))
                                 for p in cmd.points]
                self.wp[i] = 0
                self._fly_to(sp, i, 0)
                self.labels[i] = f"{cmd.nav} ({len(cmd.points)})"
            if cmd.land:
                if cmd.nav in ("goto", "waypoints"):
                    self.land_at_end.add(i)
                else:
                    self._land(sp, i, ground)

    def _fly_to(self, sp: np.ndarray, i: int, k: int) -> None:
        lat, lon, alt = self.route[i][k]
        self._hold(sp, i, lat, lon)
        if alt is not None:
            self._set(sp, i, ALT, alt)

    def _land(self, sp: np.ndarray, i: int, ground: float) -> None:
        self.landing.add(i)
        self._set(sp, i, ALT, ground - LAND_BELOW_M)
        self.labels[i] = "land"

    def _orbit(self, states: np.ndarray, sp: np.ndarray, i: int) -> None:
        """Hold a point ahead on the circle: about two seconds of flight at the
        speed limit, between 0.2 and 1 radian of arc."""
        cn, ce, radius, cw = self.orbit[i]
        n, e, _ = self.frame.geodetic_to_ned([states[i, _S["lat_deg"]]],
                                             [states[i, _S["lon_deg"]]], [self.frame.alt_m])
        angle = math.atan2(float(e[0]) - ce, float(n[0]) - cn)
        lead = min(max(2.0 * self.speed.get(i, DEFAULT_SPEED_MPS) / radius, 0.2), 1.0)
        angle += lead if cw else -lead
        lat, lon = self.frame.place(cn + radius * math.cos(angle), ce + radius * math.sin(angle),
                                    self.frame.alt_m)
        self._hold(sp, i, float(lat), float(lon))

    def update(self, states: np.ndarray, sp: np.ndarray) -> list[GuidanceEvent]:
        events, self.pending = self.pending, []
        for i in self.orbit:
            self._orbit(states, sp, i)
        for i in self.rows:
            s = states[i]
            speed = math.hypot(s[_S["vn_mps"]], s[_S["ve_mps"]])
            if i in self.route and self.route[i]:
                k = self.wp[i]
                lat, lon, _ = self.route[i][k]
                n, e, _ = self.frame.geodetic_to_ned([lat, s[_S["lat_deg"]]],
                                                     [lon, s[_S["lon_deg"]]],
                                                     [self.frame.alt_m] * 2)
                d = math.hypot(float(n[0] - n[1]), float(e[0] - e[1]))
                last = k == len(self.route[i]) - 1
                if not last and d < PASS_M:
                    events.append(GuidanceEvent("waypoint_reached", i, {"index": k}))
                    self.wp[i] = k + 1
                    self._fly_to(sp, i, k + 1)
                elif last and d < ARRIVE_M and speed < 0.3:
                    events.append(GuidanceEvent("goal_reached", i, {
                        "lat_deg": lat, "lon_deg": lon}))
                    self.route[i] = []
                    self.labels[i] = "arrived"
                    if i in self.land_at_end:
                        self.land_at_end.discard(i)
                        self._land(sp, i, float(s[_S["alt_msl_m"]] - s[_S["alt_agl_m"]]))
            if i in self.landing and s[_S["alt_agl_m"]] < 0.3 and abs(s[_S["vd_mps"]]) < 0.2:
                self.landing.discard(i)
                self._set(sp, i, ENGAGE, 0.0)
                self.labels[i] = "landed"
                events.append(GuidanceEvent("landed", i, {}))
        return events
