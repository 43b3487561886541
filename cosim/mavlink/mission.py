"""The mission of one vehicle as ArduPlane keeps it: items, the upload in
progress, and the progress of the mission being flown.

Item 0 is home (ArduPilot's convention): it is never stored, whatever a
client uploads as item 0, and downloads return the vehicle's home there.
Items are kept in their MISSION_ITEM_INT form (x/y in degE7 for global
frames) whichever message carried them.

Progress is tracked from the state rows alone (the endpoint sees no guidance
events): an item counts as reached when the vehicle is within the acceptance
radius guidance uses, ``max(0.5 * v^2 / (g tan(bank limit)), 50 m)``, or has
passed the end of the leg (along-track), the same rule guidance switches
waypoints on; the final item when within ``max(loiter radius, acceptance)``.
Distances use a flat-earth approximation (well under 1 m at these ranges).

Nothing here reads the wall clock: the upload's retries and timeout count
ticks of simulation time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from cosim.guidance.commands import waypoint_accept_radius_m
from cosim.mavlink import adapter as mav

#: seconds of simulation time between re-requests of an item during an upload
UPLOAD_RETRY_S: Final[float] = 1.0
#: seconds without progress after which an upload is cancelled (ArduPilot: 8 s)
UPLOAD_TIMEOUT_S: Final[float] = 8.0
#: most items a mission may hold (excluding home)
MAX_ITEMS: Final[int] = 700

#: MISSION_CURRENT.mission_state values (MISSION_STATE enum)
STATE_NO_MISSION, STATE_NOT_STARTED, STATE_ACTIVE, STATE_COMPLETE = 1, 2, 3, 5

GLOBAL_FRAMES: Final[frozenset[int]] = frozenset((
    mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT))
#: navigation commands that need a position in a global frame
POSITION_COMMANDS: Final[frozenset[int]] = frozenset((
    mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LOITER_UNLIM, mav.MAV_CMD_NAV_TAKEOFF))
SUPPORTED_COMMANDS: Final[frozenset[int]] = POSITION_COMMANDS | {
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, mav.MAV_CMD_DO_CHANGE_SPEED}

_M_PER_DEG: Final[float] = 111_319.49


@dataclass(frozen=True)
class MissionItem:
    """One mission item in MISSION_ITEM_INT form."""

    seq: int
    frame: int
    command: int
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0

    @classmethod
    def of(cls, m: mav.Message) -> MissionItem:
        """From a MISSION_ITEM_INT, or a MISSION_ITEM (degrees in x/y for global
        frames, converted to degE7). Non-finite coordinates become INT32_MAX
        (rejected by ``check``)."""
        f = m.fields
        frame = int(f["frame"])
        x, y = float(f["x"]), float(f["y"])
        if m.name == "MISSION_ITEM" and frame in GLOBAL_FRAMES:
            x, y = x * 1e7, y * 1e7
        xi = round(x) if math.isfinite(x) and abs(x) < 2 ** 31 else 2 ** 31 - 1
        yi = round(y) if math.isfinite(y) and abs(y) < 2 ** 31 else 2 ** 31 - 1
        return cls(int(f["seq"]), frame, int(f["command"]), int(f["current"]),
                   int(f["autocontinue"]), float(f["param1"]), float(f["param2"]),
                   float(f["param3"]), float(f["param4"]), xi, yi, float(f["z"]))

    @property
    def lat_deg(self) -> float:
        return self.x / 1e7

    @property
    def lon_deg(self) -> float:
        return self.y / 1e7

    def check(self, supported: frozenset[int] = SUPPORTED_COMMANDS) -> int:
        """MAV_MISSION_ACCEPTED, or the MAV_MISSION_RESULT error for this item
        (a command outside ``supported``, the vehicle's: UNSUPPORTED)."""
        if self.command not in supported:
            return mav.MAV_MISSION_UNSUPPORTED
        if self.command in POSITION_COMMANDS:
            if self.frame not in GLOBAL_FRAMES:
                return mav.MAV_MISSION_UNSUPPORTED_FRAME
            if not -900_000_000 <= self.x <= 900_000_000:
                return mav.MAV_MISSION_INVALID_PARAM5_X
            if not -1_800_000_000 <= self.y <= 1_800_000_000:
                return mav.MAV_MISSION_INVALID_PARAM6_Y
            if not math.isfinite(self.z):
                return mav.MAV_MISSION_INVALID_PARAM7
        if self.command == mav.MAV_CMD_NAV_LOITER_UNLIM and not math.isfinite(self.param3):
            return mav.MAV_MISSION_INVALID_PARAM3
        if self.command == mav.MAV_CMD_DO_CHANGE_SPEED and not math.isfinite(self.param2):
            return mav.MAV_MISSION_INVALID_PARAM2
        return mav.MAV_MISSION_ACCEPTED

    def fields(self, as_int: bool, target: tuple[int, int], current: bool) -> dict[str, Any]:
        """The fields of a MISSION_ITEM_INT (``as_int``) or MISSION_ITEM to ``target``."""
        x: float = self.x
        y: float = self.y
        if not as_int:
            x, y = (self.x / 1e7, self.y / 1e7) if self.frame in GLOBAL_FRAMES \
                else (float(self.x), float(self.y))
        return {"target_system": target[0], "target_component": target[1], "seq": self.seq,
                "frame": self.frame, "command": self.command, "current": int(current),
                "autocontinue": self.autocontinue, "param1": self.param1,
                "param2": self.param2, "param3": self.param3, "param4": self.param4,
                "x": x, "y": y, "z": self.z, "mission_type": mav.MAV_MISSION_TYPE_MISSION}


def home_item(home: tuple[float, float, float]) -> MissionItem:
    """Item 0: home, as a waypoint at its MSL altitude."""
    return MissionItem(0, mav.MAV_FRAME_GLOBAL, mav.MAV_CMD_NAV_WAYPOINT,
                       x=round(home[0] * 1e7), y=round(home[1] * 1e7), z=float(home[2]))


@dataclass
class Upload:
    """An upload in progress: who sends it, how many items, which is next."""

    partner: tuple[int, int]  # system, component
    count: int  # including item 0
    received: list[MissionItem] = field(default_factory=list)  # items 1.. so far
    next_seq: int = 0
    last_request_tick: int = 0
    last_progress_tick: int = 0
    use_int: bool = True  # request with MISSION_REQUEST_INT (False: MISSION_REQUEST)


@dataclass(frozen=True)
class RoutePoint:
    """A navigation item being flown: its sequence number and position."""

    seq: int
    lat_deg: float
    lon_deg: float
    final: bool = False
    loiter_radius_m: float | None = None


class Mission:
    """The mission of one vehicle (see the module docstring)."""

    def __init__(self) -> None:
        self.items: list[MissionItem] = []  # seq 1..n (item 0, home, is not stored)
        self.current = 0  # the item being (or to be) flown; 0: not started
        self.upload: Upload | None = None
        self.route: list[RoutePoint] = []  # the points the active waypoints command flies
        self.leg = 0  # index into route
        self.leg_start: tuple[float, float] | None = None
        self.complete = False
        self.reported_current = 0  # the seq of the last MISSION_CURRENT sent
        self.reached: list[int] = []  # MISSION_ITEM_REACHED still to send

    @property
    def count(self) -> int:
        """Items including home (MISSION_COUNT of a download)."""
        return len(self.items) + 1

    def item(self, seq: int, home: tuple[float, float, float]) -> MissionItem | None:
        if seq == 0:
            return home_item(home)
        if 1 <= seq <= len(self.items):
            return self.items[seq - 1]
        return None

    def replace(self, items: Sequence[MissionItem]) -> None:
        """A new mission (items 1..n); flying state is reset."""
        self.items = list(items)
        self.current = 0
        self.stop()

    def stop(self) -> None:
        self.route = []
        self.leg = 0
        self.leg_start = None
        self.complete = False

    def fly(self, route: Sequence[RoutePoint], here: tuple[float, float]) -> None:
        """The waypoints command for ``route`` was just issued from ``here``."""
        self.route = list(route)
        self.leg = 0
        self.leg_start = here
        self.complete = False
        self.current = self.route[0].seq

    def state(self, auto: bool) -> dict[str, Any]:
        """MISSION_CURRENT fields (total excludes home, as ArduPilot reports)."""
        if not self.items:
            st = STATE_NO_MISSION
        elif self.complete:
            st = STATE_COMPLETE
        elif auto and self.route:
            st = STATE_ACTIVE
        else:
            st = STATE_NOT_STARTED
        return {"seq": self.current, "total": len(self.items) if self.items else 65535,
                "mission_state": st, "mission_mode": 1 if auto else 0}

    def track(self, row: Sequence[float], index: Mapping[str, int]) -> None:
        """Advance along the route from one state row (in AUTO only)."""
        if not self.route or self.complete or self.leg_start is None:
            return
        lat, lon = float(row[index["lat_deg"]]), float(row[index["lon_deg"]])
        if not (math.isfinite(lat) and math.isfinite(lon)):
            return
        p = self.route[self.leg]
        v = max(float(row[index["airspeed_mps"]]), 1.0)
        bank = float(row[index["bank_limit_deg"]])
        if not 5.0 <= bank <= 75.0:
            bank = 45.0
        accept = waypoint_accept_radius_m(v, bank)
        coslat = math.cos(math.radians(p.lat_deg))
        bn = (p.lat_deg - lat) * _M_PER_DEG
        be = (p.lon_deg - lon) * _M_PER_DEG * coslat
        dist = math.hypot(bn, be)
        if p.final:
            if dist <= max(p.loiter_radius_m or 0.0, accept):
                self.reached.append(p.seq)
                self.complete = True
            return
        a_lat, a_lon = self.leg_start
        dn = (p.lat_deg - a_lat) * _M_PER_DEG
        de = (p.lon_deg - a_lon) * _M_PER_DEG * coslat
        length = math.hypot(dn, de)
        pn = (lat - a_lat) * _M_PER_DEG
        pe = (lon - a_lon) * _M_PER_DEG * coslat
        along = (pn * dn + pe * de) / length if length > 1e-6 else length
        if dist <= accept or along >= length:
            self.reached.append(p.seq)
            self.leg_start = (p.lat_deg, p.lon_deg)
            self.leg += 1
            self.current = self.route[self.leg].seq
