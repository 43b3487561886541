"""The ground vehicle's guidance: commands to a speed and a steering angle.

Once per exchange, per vehicle:

- **route**: ``goto`` and ``waypoints`` become a route planned around the
  obstacles it knows (each grown by ``margin_m``; ``cosim.obstacles.plan_route``:
  the shortest path through their corners). A goal it cannot reach is a
  ``route_blocked`` event, and the vehicle stops.
- **steering**: pure pursuit of the route's next point,
  ``delta = atan(2 L sin(alpha) / d)``, ``alpha`` the bearing of the point from
  the heading and ``d`` its distance (at least the wheelbase).
- **speed**: the cruise speed (``airspeed_*`` commands; default the start
  speed, else 5 m/s), capped by ``sqrt(2 b s)`` so it stops exactly at the
  route's end ``s`` metres ahead, and by the same rule for the nearest
  known obstacle straight ahead (less ``STOP_SHORT_M``): it stops short
  rather than touching it. ``loiter`` and ``heading_deg`` stop it and steer straight on
  a heading respectively.
- **events**: ``waypoint_reached`` at each point, ``goal_reached`` when it is
  stopped within ``ARRIVE_M`` of the end, ``obstacle_discovered`` when its
  scout camera shows it an obstacle it did not know (it then plans again).

Altitudes in commands are ignored: a ground vehicle drives on the ground.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from cosim.core.camera import camera_pose, footprint
from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX, VehicleSpec
from cosim.guidance.commands import Command, Point
from cosim.vehicles.base import GuidanceEvent
from cosim.vehicles.ground.model import SPEED_CMD, STEER_CMD
from cosim.world.obstacles import inflate, inside, plan_route

_S = STATE_INDEX
#: within this of a route's end and stopped: arrived
ARRIVE_M = 1.0
#: how far short of a known obstacle straight ahead it stops (its routes keep
#: margin_m clear; this is the rule when something else points it at one)
STOP_SHORT_M = 0.5
DEFAULT_CRUISE_MPS = 5.0


def _ray_distance(p: np.ndarray, heading: float, polys: Sequence[np.ndarray],
                  reach: float) -> float:
    """How far ahead along ``heading`` (rad from north) the first polygon edge
    is, up to ``reach`` (inf: none)."""
    d = np.array([math.cos(heading), math.sin(heading)])
    best = math.inf
    for poly in polys:
        k = len(poly)
        for i in range(k):
            a, b = poly[i], poly[(i + 1) % k]
            s = b - a
            den = d[0] * s[1] - d[1] * s[0]
            if abs(den) < 1e-12:
                continue
            w = a - p
            t = (w[0] * s[1] - w[1] * s[0]) / den  # along the ray
            u = (w[0] * d[1] - w[1] * d[0]) / den  # along the edge
            if 0 <= t <= reach and 0 <= u <= 1:
                best = min(best, t)
    return best


class GroundGuidance:
    """See the module docstring. Rows are state rows; ``specs`` every row's spec."""

    def __init__(self, rows: Sequence[int], frame: LocalFrame, start_ne: np.ndarray,
                 channel_index: Mapping[str, int], specs: Sequence[VehicleSpec]) -> None:
        n = len(start_ne)
        self.frame = frame
        self.start_ne = start_ne
        self.c_speed, self.c_steer = channel_index[SPEED_CMD], channel_index[STEER_CMD]
        self.rows = list(rows)
        self.ids = [s.id for s in specs]  # by state row: events name vehicles by id
        self.labels = [""] * n
        self.route: dict[int, list[np.ndarray]] = {}
        self.heading: dict[int, float] = {}  # drive on a heading (rad)
        self.cruise: dict[int, float] = {}
        self.params: dict[int, dict[str, Any]] = {}
        self.known: dict[int, list[np.ndarray]] = {}  # obstacles, grown, each knows
        self.walls: dict[int, list[np.ndarray]] = {}  # the same, as they are
        self.wp: dict[int, int] = {}
        #: per vehicle: the ids of the obstacles it does not know yet, and its scout
        self.unknown: dict[int, dict[str, np.ndarray]] = {}
        self.scout: dict[int, tuple[Any, list[int]]] = {}
        for r in self.rows:
            q = specs[r].class_params
            self.params[r] = q
            self.cruise[r] = specs[r].airspeed_mps or DEFAULT_CRUISE_MPS
            known = [np.array(p) for p, k in zip(q["obstacles"], q["known"]) if k]
            self.walls[r] = known
            self.known[r] = [inflate(p, q["margin_m"]) for p in known]
            self.unknown[r] = {oid: np.array(p) for oid, p, k in
                               zip(q["obstacle_ids"], q["obstacles"], q["known"]) if not k}
            cam = q.get("scout_camera")
            if cam is not None:
                self.scout[r] = (cam, list(cam.vehicles))

    def resolve(self, p: Point, i: int) -> np.ndarray:
        if p.frame == "geodetic":
            n, e, _ = self.frame.geodetic_to_ned(p.a, p.b, self.frame.alt_m)
            return np.array([float(n), float(e)])
        if p.frame == "start":
            return self.start_ne[i] + np.array([p.a, p.b])
        return np.array([p.a, p.b])

    def _here(self, states: np.ndarray, i: int) -> np.ndarray:
        n, e, _ = self.frame.geodetic_to_ned(states[i, _S["lat_deg"]], states[i, _S["lon_deg"]],
                                             states[i, _S["alt_msl_m"]])
        return np.array([float(n), float(e)])

    def learn(self, i: int, polygon: np.ndarray, states: np.ndarray) -> bool:
        """Vehicle ``i`` now knows of the obstacle ``polygon`` (a camera saw it):
        its route is planned again around it. False: no route is left."""
        self.walls[i].append(polygon)
        self.known[i].append(inflate(polygon, self.params[i]["margin_m"]))
        if i in self.route and self.route[i]:
            goal = self.route[i][-1]
            if not self._plan(i, self._here(states, i), [goal]):
                self.labels[i] = "blocked"
                return False
        return True

    def _plan(self, i: int, here: np.ndarray, goals: list[np.ndarray]) -> bool:
        route: list[np.ndarray] = []
        at = here
        for g in goals:
            leg = plan_route(at, g, self.known[i])
            if leg is None:
                self.route[i] = []
                return False
            route += leg
            at = g
        self.route[i] = route
        self.wp[i] = 0
        return True

    def command(self, rows: list[int], cmd: Command, states: np.ndarray,
                sp: np.ndarray) -> None:
        self.events_pending: list[GuidanceEvent] = getattr(self, "events_pending", [])
        for i in rows:
            if cmd.airspeed_mps is not None:
                self.cruise[i] = min(cmd.airspeed_mps, self.params[i]["max_speed_mps"])
            if cmd.heading_deg is not None:
                self.route.pop(i, None)
                self.heading[i] = math.radians(cmd.heading_deg)
                self.labels[i] = f"heading {cmd.heading_deg:g}"
            if cmd.nav == "loiter":
                self.route.pop(i, None)
                self.heading.pop(i, None)
                self.labels[i] = "hold"
            elif cmd.nav in ("goto", "waypoints"):
                self.heading.pop(i, None)
                goals = [self.resolve(p, i) for p in cmd.points]
                if self._plan(i, self._here(states, i), goals):
                    self.labels[i] = f"{cmd.nav} ({len(self.route[i])} legs)"
                else:
                    self.labels[i] = "blocked"
                    self.events_pending.append(GuidanceEvent(
                        "route_blocked", i, {"goal_north_m": float(goals[-1][0]),
                                             "goal_east_m": float(goals[-1][1])}))
            self._drive(i, states, sp)

    def update(self, states: np.ndarray, sp: np.ndarray) -> list[GuidanceEvent]:
        events: list[GuidanceEvent] = getattr(self, "events_pending", [])
        self.events_pending = []
        views: dict[int, np.ndarray] = {}  # scout row -> its camera's ground footprint
        for i in self.rows:
            if i in self.scout and self.unknown[i]:
                events += self._discover(i, states, views)
            events += self._drive(i, states, sp)
        return events

    def _discover(self, i: int, states: np.ndarray,
                  views: dict[int, np.ndarray]) -> list[GuidanceEvent]:
        """Learn the unknown obstacles its scouts' cameras see now."""
        cam, scouts = self.scout[i]
        events = []
        for r in scouts:
            if r not in views:
                views[r] = self._footprint(cam, states, r)
            fp = views[r]
            for oid, poly in list(self.unknown[i].items()):
                if inside(fp, poly).any() or inside(poly, fp).any():
                    del self.unknown[i][oid]
                    ok = self.learn(i, poly, states)
                    events.append(GuidanceEvent("obstacle_discovered", i, {
                        "obstacle": oid, "by": self.ids[r]}))
                    if not ok:
                        events.append(GuidanceEvent("route_blocked", i, {"obstacle": oid}))
        return events

    def _footprint(self, cam: Any, states: np.ndarray, r: int) -> np.ndarray:
        """The ground that camera on vehicle row ``r`` sees, in the scenario frame."""
        s = states[r]
        ground = float(s[_S["alt_msl_m"]] - s[_S["alt_agl_m"]])
        pose = camera_pose(cam, s[_S["lat_deg"]], s[_S["lon_deg"]], s[_S["alt_msl_m"]],
                           s[_S["roll_deg"]], s[_S["pitch_deg"]], s[_S["yaw_deg"]], ground)
        fp = footprint(cam, pose, max_range_m=2000.0)
        n, e, _ = self.frame.geodetic_to_ned(s[_S["lat_deg"]], s[_S["lon_deg"]], ground)
        return fp + np.array([float(n), float(e)])  # L is centred under the vehicle

    def _drive(self, i: int, states: np.ndarray, sp: np.ndarray) -> list[GuidanceEvent]:
        q = self.params[i]
        here = self._here(states, i)
        psi = math.radians(float(states[i, _S["yaw_deg"]]))
        v = float(states[i, _S["airspeed_mps"]])
        brake, L = q["brake_mps2"], q["wheelbase_m"]
        events: list[GuidanceEvent] = []
        route = self.route.get(i)
        if route:
            k = self.wp[i]
            target = route[k]
            d = float(np.hypot(*(target - here)))
            while k < len(route) - 1 and d < max(2.0, 0.5 * v + L):
                events.append(GuidanceEvent("waypoint_reached", i, {
                    "index": k, "north_m": float(target[0]), "east_m": float(target[1])}))
                k += 1
                target = route[k]
                d = float(np.hypot(*(target - here)))
            self.wp[i] = k
            left = d + sum(float(np.hypot(*(route[j + 1] - route[j])))
                           for j in range(k, len(route) - 1))
            bearing = math.atan2(target[1] - here[1], target[0] - here[0])
            alpha = math.remainder(bearing - psi, 2 * math.pi)
            steer = math.atan2(2 * L * math.sin(alpha), max(d, L))
            speed = min(self.cruise[i], math.sqrt(2 * brake * max(left - 0.2, 0.0)))
            if left < ARRIVE_M and v < 0.05:
                events.append(GuidanceEvent("goal_reached", i, {
                    "north_m": float(route[-1][0]), "east_m": float(route[-1][1])}))
                self.route[i] = []
                self.labels[i] = "arrived"
                speed, steer = 0.0, 0.0
        elif i in self.heading:
            alpha = math.remainder(self.heading[i] - psi, 2 * math.pi)
            steer = math.atan2(2 * L * math.sin(alpha), max(4 * L, v))
            speed = self.cruise[i]
        else:
            speed, steer = 0.0, 0.0
        # never drive into what it knows is there: stop STOP_SHORT_M short of it
        reach = v * v / (2 * brake) + STOP_SHORT_M + 5.0
        ahead = _ray_distance(here, psi, self.walls[i], reach)
        if math.isfinite(ahead):
            speed = min(speed, math.sqrt(2 * brake * max(ahead - STOP_SHORT_M, 0.0)))
        sp[i, self.c_speed] = speed
        sp[i, self.c_steer] = math.degrees(steer)
        return events
