"""A vehicle's mission flown item by item (``MissionRunner``, once per
exchange from the state rows; the plan is ``cosim.mavlink.mission``'s): one
navigation item at a time, each as the command its class's personality
makes of it (``Personality.nav_vocab``); the DO and CONDITION items after a
navigation item run as soon as it starts, each CONDITION holding back the DO
items after it (CONDITION_DELAY: seconds; CONDITION_DISTANCE: metres from
the item's point); DO_JUMP jumps back with its repeat count (-1: for ever).
An item is reached (MISSION_ITEM_REACHED) when:

- NAV_WAYPOINT: within its acceptance radius (param2, else the class's:
  ``max(0.5 v^2 / (g tan(bank limit)), 50 m)`` for a fixed-wing, which also
  counts a waypoint whose leg it has passed), then after its hold time
  (param1, rotorcraft and rovers);
- NAV_LOITER_TURNS: after param1 turns round the centre, counted from the
  first time within its radius plus the acceptance radius;
- NAV_LOITER_TIME: param1 seconds after reaching the circle;
- NAV_LOITER_TO_ALT: on the circle within 5 m of its altitude;
- NAV_TAKEOFF: within 5 m of its altitude (1 m for rotorcraft);
- NAV_LAND, and NAV_RETURN_TO_LAUNCH of a class that lands there: landed;
  otherwise RTL at home (the mission then ends, loitering there);
- NAV_LOITER_UNLIM: never.

Distances use a flat-earth approximation (well under 1 m at these ranges).
Nothing here reads the wall clock: times count ticks of simulation time.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from cosim.core.state import STATE_INDEX as _S
from cosim.mavlink import adapter as mav
from cosim.mavlink.mission import (
    ALT_TOLERANCE_M,
    CAMERA_ITEMS,
    CONDITIONS,
    MAX_JUMPS_PER_ADVANCE,
    NAV_COMMANDS,
    Mission,
    MissionItem,
    NavState,
    flat_ne,
)
from cosim.mavlink.outcome import Outcome, roi_vocab, text, vocab

if TYPE_CHECKING:
    from cosim.mavlink.services.base import Context
    from cosim.mavlink.vehicle import MavVehicle

M = mav


class MissionRunner:
    """Flies the missions of the vehicles of one endpoint (see the module
    docstring); every command goes out in an ``Outcome``."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx

    # -- starting and advancing ----------------------------------------------------
    def start(self, v: MavVehicle, seq: int, tick: int, out: Outcome) -> str | None:
        """Fly the mission from item ``seq``; why not (None: flying)."""
        ms = v.mission
        if seq <= 1:
            ms.jumps = {}
            ms.speed_mps = None
        ms.stop()
        return self._advance(v, max(seq, 1), tick, out, first=True)

    def _advance(self, v: MavVehicle, seq: int, tick: int, out: Outcome,
                 first: bool = False) -> str | None:
        """Run the items from ``seq`` up to the next navigation item and start
        it; at the end of the list the mission is complete."""
        ms = v.mission
        jumps = 0
        i = seq
        while 1 <= i <= len(ms.items):
            it = ms.items[i - 1]
            if it.seq in ms.refused:
                self.ctx.counts["mission_items_skipped"] += 1
                i += 1
                continue
            if it.command == M.MAV_CMD_DO_JUMP:
                jumps += 1
                if jumps > MAX_JUMPS_PER_ADVANCE:
                    out.replies.extend(text(f"Mission: DO_JUMP loop at item {it.seq} "
                                            f"without navigation; stopped"))
                    return self._end(v, out, first, "a DO_JUMP loop without navigation")
                left = ms.jumps.setdefault(it.seq, int(it.param2))
                if left != 0:
                    if left > 0:
                        ms.jumps[it.seq] = left - 1
                    i = int(it.param1)
                else:
                    i += 1
                continue
            if it.command in NAV_COMMANDS:
                problem = self._start_nav(v, it, tick, out)
                if problem is None:
                    ms.current = it.seq
                    ms.do_queue = self._dos_after(ms, i)
                    ms.waiting = None
                    self._run_dos(v, tick, out)
                    return None
                out.replies.extend(text(f"Mission item {it.seq}: "
                                        f"{mav.command_name(it.command)}: {problem}; skipped"))
                self.ctx.counts["mission_items_skipped"] += 1
                i += 1
                continue
            if first:  # DO items before the first navigation item; later ones ran
                self._do(v, it, tick, out)  # (or were abandoned) with the item before
            i += 1
        return self._end(v, out, first, "no navigation items left in the mission")

    def _end(self, v: MavVehicle, out: Outcome, first: bool, why: str) -> str | None:
        if first:
            return why
        v.mission.complete = True
        v.mission.do_queue = []
        return None

    @staticmethod
    def _dos_after(ms: Mission, i: int) -> list[MissionItem]:
        """The DO and CONDITION items after item ``i``, up to the next
        navigation item or DO_JUMP."""
        out = []
        for it in ms.items[i:]:
            if it.command in NAV_COMMANDS or it.command == M.MAV_CMD_DO_JUMP:
                break
            if it.seq not in ms.refused:
                out.append(it)
        return out

    def _start_nav(self, v: MavVehicle, it: MissionItem, tick: int, out: Outcome) -> str | None:
        ms = v.mission
        row = v.row_or_raise()
        here = (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]))
        prev = (ms.nav.lat_deg, ms.nav.lon_deg) if ms.nav is not None else here
        d = v.personality.nav_vocab(self.ctx, v, it, prev)
        if isinstance(d, str):
            return d
        cw = d.pop("cw", None)  # the loiter direction of a goto's end, not vocabulary
        cmd = vocab(d)
        if isinstance(cmd, str):
            return cmd
        problem = self.ctx.unsafe(v, cmd)
        if problem is not None:
            return problem
        target = _target_of(d, prev)
        alt = self.ctx.alt(v, it.frame, it.z) if it.command != M.MAV_CMD_NAV_RETURN_TO_LAUNCH \
            else None
        radius = v.personality.loiter_radius_m(v, d)
        ms.nav = NavState(it, target[0], target[1], alt, radius, prev, tick)
        if cw is not None:
            cmd = replace(cmd, loiter_cw=bool(cw))
        out.commands.append(cmd)
        return None

    # -- every exchange --------------------------------------------------------------
    def update(self, v: MavVehicle, tick: int, out: Outcome) -> None:
        """Progress of the mission being flown from the latest state row."""
        ms = v.mission
        row = v.row_values
        if ms.nav is None or ms.complete or row is None:
            return
        lat, lon = float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]])
        if not (math.isfinite(lat) and math.isfinite(lon)):
            return
        self._run_dos(v, tick, out)
        if self._nav_done(v, ms.nav, row, lat, lon, tick):
            ms.reached.append(ms.nav.item.seq)
            self.ctx.counts["mission_items_reached"] += 1
            if ms.nav.item.command == M.MAV_CMD_NAV_LAND or (
                    ms.nav.item.command == M.MAV_CMD_NAV_RETURN_TO_LAUNCH
                    and v.personality.rtl_lands):
                v.armed = False  # ArduPilot disarms once landed
            self._advance(v, ms.nav.item.seq + 1, tick, out)

    def _run_dos(self, v: MavVehicle, tick: int, out: Outcome) -> None:
        ms = v.mission
        while ms.do_queue:
            it = ms.do_queue[0]
            if it.command in CONDITIONS:
                if ms.waiting is None or ms.waiting[0] != it.seq:
                    ms.waiting = (it.seq, tick)
                if not self._condition_met(v, it, ms.waiting[1], tick):
                    return
                ms.waiting = None
            else:
                self._do(v, it, tick, out)
            ms.do_queue.pop(0)

    def _condition_met(self, v: MavVehicle, it: MissionItem, since: int, tick: int) -> bool:
        if it.command == M.MAV_CMD_CONDITION_DELAY:
            return tick - since >= it.param1 * self.ctx.physics_hz
        nav, row = v.mission.nav, v.row_values  # CONDITION_DISTANCE
        if nav is None or row is None:
            return True
        d = math.hypot(*flat_ne(nav.lat_deg, nav.lon_deg, float(row[_S["lat_deg"]]),
                                float(row[_S["lon_deg"]])))
        return d <= it.param1

    def _do(self, v: MavVehicle, it: MissionItem, tick: int, out: Outcome) -> None:
        """Run one DO item."""
        ms = v.mission
        c = it.command
        d: dict[str, Any] | None = None
        if c == M.MAV_CMD_DO_CHANGE_SPEED:
            if it.param2 > 0:
                ms.speed_mps = it.param2
                problem = v.personality.speed_problem(v, it.param2)
                if problem is None and v.armed:
                    d = {"airspeed_mps": it.param2}
                elif problem is not None:
                    out.replies.extend(text(f"Mission item {it.seq}: {problem}"))
        elif c == M.MAV_CMD_DO_SET_HOME:
            row = v.row_or_raise()
            if it.param1 == 1 or it.here:
                v.home = (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]),
                          float(row[_S["alt_msl_m"]] - row[_S["alt_agl_m"]]))
            else:
                a = self.ctx.alt(v, it.frame, it.z)
                alt = a[1] if a is not None and a[0] == "alt_msl_m" else v.home[2]
                v.home = (it.lat_deg, it.lon_deg, alt)
            out.replies.append(("HOME_POSITION", v.fields("HOME_POSITION", tick)))
        elif c in (M.MAV_CMD_DO_SET_ROI, M.MAV_CMD_DO_SET_ROI_LOCATION):
            d = roi_vocab(None if it.here else (it.lat_deg, it.lon_deg),
                          self.ctx.alt(v, it.frame, it.z))
        elif c == M.MAV_CMD_DO_SET_ROI_NONE:
            d = roi_vocab(None, None)
        elif c in CAMERA_ITEMS:
            d = camera_vocab(it)
        if d is None:
            return
        cmd = vocab(d)
        if isinstance(cmd, str):
            out.replies.extend(text(f"Mission item {it.seq}: {cmd}"))
            self.ctx.counts["mission_items_skipped"] += 1
            return
        out.commands.append(cmd)

    def _nav_done(self, v: MavVehicle, nav: NavState, row: list[float], lat: float,
                  lon: float, tick: int) -> bool:
        p = v.personality
        c = nav.item.command
        hz = self.ctx.physics_hz
        n, e = flat_ne(nav.lat_deg, nav.lon_deg, lat, lon)
        dist = math.hypot(n, e)
        accept = p.accept_radius_m(v, row)
        if c == M.MAV_CMD_NAV_WAYPOINT:
            if nav.item.param2 > 0:
                accept = nav.item.param2
            if nav.arrived_tick is None:
                passed = p.passes_waypoints and _passed(nav, lat, lon)
                if dist > accept and not passed:
                    return False
                nav.arrived_tick = tick
            hold = nav.item.param1 if p.waypoint_hold else 0.0
            return tick - nav.arrived_tick >= hold * hz
        if c == M.MAV_CMD_NAV_TAKEOFF:
            return self._at_alt(v, nav, row, p.takeoff_tolerance_m)
        if c == M.MAV_CMD_NAV_LAND:
            return p.landed(row)
        if c == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            if p.rtl_lands:
                return p.landed(row)
            return dist <= max(nav.radius_m, accept)
        if c == M.MAV_CMD_NAV_LOITER_UNLIM:
            return False
        # the loiters with an end: on the circle first
        if nav.arrived_tick is None:
            if dist > nav.radius_m + accept:
                return False
            nav.arrived_tick = tick
        if c == M.MAV_CMD_NAV_LOITER_TIME:
            return tick - nav.arrived_tick >= nav.item.param1 * hz
        if c == M.MAV_CMD_NAV_LOITER_TO_ALT:
            return self._at_alt(v, nav, row, ALT_TOLERANCE_M)
        # LOITER_TURNS: the angle swept round the centre
        if nav.radius_m < 1.0:
            return True  # a point: nothing to turn round
        angle = math.atan2(e, n)
        if nav.last_angle is not None:
            nav.swept_rad += abs(math.remainder(angle - nav.last_angle, math.tau))
        nav.last_angle = angle
        return nav.swept_rad >= abs(nav.item.param1) * math.tau

    def _at_alt(self, v: MavVehicle, nav: NavState, row: list[float], tol: float) -> bool:
        if nav.alt is None:
            return True
        key, want = nav.alt
        have = float(row[_S["alt_agl_m"]] if key == "alt_agl_m" else row[_S["alt_msl_m"]])
        if nav.item.command == M.MAV_CMD_NAV_TAKEOFF:
            return have >= want - tol  # a take-off never descends
        return abs(have - want) <= tol


def _target_of(d: dict[str, Any], prev: tuple[float, float]) -> tuple[float, float]:
    """The point a vocabulary mapping flies to (``prev``: none)."""
    for key in ("goto", "loiter"):
        p = d.get(key)
        if isinstance(p, dict):
            p = p.get("center", p)
            if isinstance(p, dict) and "lat_deg" in p:
                return float(p["lat_deg"]), float(p["lon_deg"])
    return prev


def _passed(nav: NavState, lat: float, lon: float) -> bool:
    """Whether the vehicle has passed the end of its leg (along-track)."""
    a_lat, a_lon = nav.leg_start
    dn, de = flat_ne(a_lat, a_lon, nav.lat_deg, nav.lon_deg)
    length = math.hypot(dn, de)
    if length < 1e-6:
        return False
    pn, pe = flat_ne(a_lat, a_lon, lat, lon)
    return (pn * dn + pe * de) / length >= length


def camera_vocab(it: MissionItem) -> dict[str, Any] | None:
    """The ``camera`` command of a camera item (None: nothing to do)."""
    c = it.command
    cam: dict[str, Any]
    if c == M.MAV_CMD_DO_SET_CAM_TRIGG_DIST:
        if it.param1 > 0:
            cam = {"distance_m": it.param1}
        elif it.param3 == 1:
            cam = {"shoot": True}
        else:
            cam = {"stop": True}
    elif c == M.MAV_CMD_IMAGE_START_CAPTURE:
        interval, total = it.param2, int(it.param3)
        if interval <= 0 or total == 1:
            cam = {"shoot": True}
        else:
            cam = {"interval_s": interval}
            if total > 1:
                cam["count"] = total
    elif c == M.MAV_CMD_IMAGE_STOP_CAPTURE:
        cam = {"stop": True}
    elif c == M.MAV_CMD_DO_DIGICAM_CONTROL:
        if it.x not in (1, 10_000_000):  # param5 "shoot" (a float item's 1.0 scaled as degE7)
            return None
        cam = {"shoot": True}
    else:
        return None
    return {"camera": cam}
