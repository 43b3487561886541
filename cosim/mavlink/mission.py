"""The missions of one vehicle as ArduPilot keeps them: the plan (mission,
fence and rally point lists), the upload in progress, and where the flight
of the mission stands (``cosim.mavlink.mission_runner`` flies it).

Item 0 of the mission list is home (ArduPilot's convention): it is never
stored, whatever a client uploads as item 0, and downloads return the
vehicle's home there. Fence and rally lists have no home item. Items are
kept in their MISSION_ITEM_INT form (x/y in degE7 for global frames)
whichever message carried them.

Upload: an item that is malformed (a position outside the globe, a frame
without an altitude cosim knows, a non-finite parameter, a DO_JUMP to an
item that does not exist) ends the upload with its exact MAV_MISSION_*
result and leaves the plan on board as it was, as the protocol says. An item
that is well formed but that this vehicle's class cannot fly (a command
outside its personality's ``mission_items``) is stored, reported once by a
STATUSTEXT naming the item and its MAV_MISSION_* result, and skipped in
flight, as ArduPilot skips commands it cannot run; the rest of the plan is
flown as uploaded.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

from cosim.core.state import STATE_INDEX as _S
from cosim.mavlink import adapter as mav

if TYPE_CHECKING:
    from cosim.mavlink.services.base import Context
    from cosim.mavlink.vehicle import MavVehicle

#: seconds of simulation time between re-requests of an item during an upload
UPLOAD_RETRY_S: Final[float] = 1.0
#: seconds without progress after which an upload is cancelled (ArduPilot: 8 s)
UPLOAD_TIMEOUT_S: Final[float] = 8.0
#: most items a list may hold: mission (excluding home), fence, rally
MAX_ITEMS: Final[int] = 700
MAX_FENCE_ITEMS: Final[int] = 200
MAX_RALLY_ITEMS: Final[int] = 50
#: DO_JUMPs followed in one advance before the mission is stopped as a loop
#: without navigation (e.g. an item jumping to itself for ever)
MAX_JUMPS_PER_ADVANCE: Final[int] = 64
#: how close (m) to its altitude a take-off or LOITER_TO_ALT counts as there
ALT_TOLERANCE_M: Final[float] = 5.0

#: MISSION_CURRENT.mission_state values (MISSION_STATE enum)
STATE_NO_MISSION, STATE_NOT_STARTED, STATE_ACTIVE, STATE_COMPLETE = 1, 2, 3, 5

M = mav
GLOBAL_FRAMES: Final[frozenset[int]] = frozenset((
    M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT))
#: navigation items: one is flown at a time
NAV_COMMANDS: Final[frozenset[int]] = frozenset((
    M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_UNLIM, M.MAV_CMD_NAV_LOITER_TURNS,
    M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_CMD_NAV_LAND,
    M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LOITER_TO_ALT))
#: items whose x/y/z are a position in a global frame (x = y = 0: "here")
POSITION_COMMANDS: Final[frozenset[int]] = frozenset((
    M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_UNLIM, M.MAV_CMD_NAV_LOITER_TURNS,
    M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_TAKEOFF,
    M.MAV_CMD_NAV_LOITER_TO_ALT, M.MAV_CMD_DO_SET_HOME, M.MAV_CMD_DO_SET_ROI,
    M.MAV_CMD_DO_SET_ROI_LOCATION))
LOITERS: Final[frozenset[int]] = frozenset((
    M.MAV_CMD_NAV_LOITER_UNLIM, M.MAV_CMD_NAV_LOITER_TURNS, M.MAV_CMD_NAV_LOITER_TIME,
    M.MAV_CMD_NAV_LOITER_TO_ALT))
CONDITIONS: Final[frozenset[int]] = frozenset((
    M.MAV_CMD_CONDITION_DELAY, M.MAV_CMD_CONDITION_DISTANCE))
CAMERA_ITEMS: Final[frozenset[int]] = frozenset((
    M.MAV_CMD_DO_SET_CAM_TRIGG_DIST, M.MAV_CMD_IMAGE_START_CAPTURE,
    M.MAV_CMD_IMAGE_STOP_CAPTURE, M.MAV_CMD_DO_DIGICAM_CONTROL))
#: DO and CONDITION items every ArduPilot-like class runs (``mission_runner``)
COMMON_DO_ITEMS: Final[frozenset[int]] = CONDITIONS | CAMERA_ITEMS | frozenset((
    M.MAV_CMD_DO_JUMP, M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_CMD_DO_SET_HOME, M.MAV_CMD_DO_SET_ROI,
    M.MAV_CMD_DO_SET_ROI_LOCATION, M.MAV_CMD_DO_SET_ROI_NONE))
FENCE_ITEMS: Final[frozenset[int]] = frozenset((
    M.MAV_CMD_NAV_FENCE_RETURN_POINT, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
    M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION))
RALLY_ITEMS: Final[frozenset[int]] = frozenset((M.MAV_CMD_NAV_RALLY_POINT,))
#: what each list may hold and how many
LIST_RULES: Final[dict[int, tuple[frozenset[int] | None, int]]] = {
    M.MAV_MISSION_TYPE_MISSION: (None, MAX_ITEMS),
    M.MAV_MISSION_TYPE_FENCE: (FENCE_ITEMS, MAX_FENCE_ITEMS),
    M.MAV_MISSION_TYPE_RALLY: (RALLY_ITEMS, MAX_RALLY_ITEMS)}

_M_PER_DEG: Final[float] = 111_319.49


def result_name(result: int) -> str:
    """MAV_MISSION_RESULT number -> its name (MAV_MISSION_UNSUPPORTED, ...)."""
    entry = mav.enum_entry("MAV_MISSION_RESULT", result)
    return entry or f"MAV_MISSION_RESULT {result}"


def flat_ne(lat0: float, lon0: float, lat: float, lon: float) -> tuple[float, float]:
    """(north, east) metres of (lat, lon) from (lat0, lon0), flat earth."""
    return ((lat - lat0) * _M_PER_DEG,
            (lon - lon0) * _M_PER_DEG * math.cos(math.radians(lat0)))


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
    mission_type: int = M.MAV_MISSION_TYPE_MISSION

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
                   float(f["param3"]), float(f["param4"]), xi, yi, float(f["z"]),
                   int(f.get("mission_type", M.MAV_MISSION_TYPE_MISSION)))

    @property
    def lat_deg(self) -> float:
        return self.x / 1e7

    @property
    def lon_deg(self) -> float:
        return self.y / 1e7

    @property
    def here(self) -> bool:
        """Whether its position means "where the vehicle is" (x = y = 0)."""
        return self.x == 0 and self.y == 0

    def check(self, count: int = 0) -> int:
        """MAV_MISSION_ACCEPTED, or the MAV_MISSION_RESULT error that makes this
        item malformed (``count``: the items of the list, home included, for
        DO_JUMP's target). Whether the vehicle can fly it is not asked here."""
        c = self.command
        allowed, _ = LIST_RULES.get(self.mission_type, (frozenset(), 0))
        if allowed is not None and c not in allowed:
            return M.MAV_MISSION_UNSUPPORTED
        if allowed is None and (c in FENCE_ITEMS or c in RALLY_ITEMS):  # in the wrong list
            return M.MAV_MISSION_UNSUPPORTED
        if c in POSITION_COMMANDS or c in FENCE_ITEMS or c in RALLY_ITEMS:
            if self.frame not in GLOBAL_FRAMES:
                return M.MAV_MISSION_UNSUPPORTED_FRAME
            if not -900_000_000 <= self.x <= 900_000_000:
                return M.MAV_MISSION_INVALID_PARAM5_X
            if not -1_800_000_000 <= self.y <= 1_800_000_000:
                return M.MAV_MISSION_INVALID_PARAM6_Y
            if not math.isfinite(self.z):
                return M.MAV_MISSION_INVALID_PARAM7
        p1, p2, p3 = self.param1, self.param2, self.param3
        if c in LOITERS and c != M.MAV_CMD_NAV_LOITER_TO_ALT and not math.isfinite(p3):
            return M.MAV_MISSION_INVALID_PARAM3
        if c == M.MAV_CMD_NAV_LOITER_TO_ALT and not math.isfinite(p2):
            return M.MAV_MISSION_INVALID_PARAM2
        if c == M.MAV_CMD_NAV_LOITER_TURNS and not (math.isfinite(p1) and 0 < p1 <= 1000):
            return M.MAV_MISSION_INVALID_PARAM1
        if c in (M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_CONDITION_DELAY,
                 M.MAV_CMD_CONDITION_DISTANCE) and not (math.isfinite(p1) and p1 >= 0):
            return M.MAV_MISSION_INVALID_PARAM1
        if c == M.MAV_CMD_NAV_WAYPOINT and not (math.isfinite(p1) and math.isfinite(p2)):
            return M.MAV_MISSION_INVALID_PARAM1 if not math.isfinite(p1) \
                else M.MAV_MISSION_INVALID_PARAM2
        if c == M.MAV_CMD_DO_CHANGE_SPEED and not math.isfinite(p2):
            return M.MAV_MISSION_INVALID_PARAM2
        if c == M.MAV_CMD_DO_JUMP:
            if not (math.isfinite(p1) and p1 == int(p1) and 1 <= p1 < max(count, 2)):
                return M.MAV_MISSION_INVALID_PARAM1
            if not (math.isfinite(p2) and p2 == int(p2) and -1 <= p2 <= 10_000):
                return M.MAV_MISSION_INVALID_PARAM2
        if c in (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                 M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION) \
                and not (math.isfinite(p1) and p1 == int(p1) and 3 <= p1 <= MAX_FENCE_ITEMS):
            return M.MAV_MISSION_INVALID_PARAM1
        if c in (M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION) \
                and not (math.isfinite(p1) and p1 > 0):
            return M.MAV_MISSION_INVALID_PARAM1
        if c in CAMERA_ITEMS and not all(math.isfinite(p) for p in (p1, p2, p3, self.param4)):
            return M.MAV_MISSION_INVALID_PARAM1
        return M.MAV_MISSION_ACCEPTED

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
                "x": x, "y": y, "z": self.z, "mission_type": self.mission_type}


def home_item(home: tuple[float, float, float]) -> MissionItem:
    """Item 0: home, as a waypoint at its MSL altitude."""
    return MissionItem(0, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT,
                       x=round(home[0] * 1e7), y=round(home[1] * 1e7), z=float(home[2]))


@dataclass
class Upload:
    """An upload in progress: who sends it, which list, how many items, which is next."""

    partner: tuple[int, int]  # system, component
    count: int  # including item 0 for the mission list
    received: list[MissionItem] = field(default_factory=list)  # items stored so far
    next_seq: int = 0
    last_request_tick: int = 0
    last_progress_tick: int = 0
    use_int: bool = True  # request with MISSION_REQUEST_INT (False: MISSION_REQUEST)
    mission_type: int = M.MAV_MISSION_TYPE_MISSION
    #: (seq, result) of the items the vehicle cannot fly (stored, skipped in flight)
    refused: list[tuple[int, int]] = field(default_factory=list)


@dataclass
class NavState:
    """The navigation item being flown."""

    item: MissionItem
    lat_deg: float
    lon_deg: float
    alt: tuple[str, float] | None  # (vocabulary key, metres) of its altitude
    radius_m: float  # its loiter radius (0: a point)
    leg_start: tuple[float, float]
    start_tick: int
    arrived_tick: int | None = None
    swept_rad: float = 0.0
    last_angle: float | None = None


class Mission:
    """The plan and flight state of one vehicle (see the module docstring)."""

    def __init__(self) -> None:
        self.items: list[MissionItem] = []  # seq 1..n (item 0, home, is not stored)
        self.fence: list[MissionItem] = []
        self.rally: list[MissionItem] = []
        self.refused: dict[int, int] = {}  # seq -> MAV_MISSION result: skipped in flight
        self.current = 0  # the item being (or to be) flown; 0: not started
        self.upload: Upload | None = None
        self.nav: NavState | None = None
        self.do_queue: list[MissionItem] = []
        self.waiting: tuple[int, int] | None = None  # (condition seq, tick it started)
        self.jumps: dict[int, int] = {}  # DO_JUMP seq -> jumps left (-1: for ever)
        self.speed_mps: float | None = None
        self.complete = False
        self.reported_current = 0  # the seq of the last MISSION_CURRENT sent
        self.reached: list[int] = []  # MISSION_ITEM_REACHED still to send
        self.breached = False  # outside the fence (an RTL was commanded)

    @property
    def count(self) -> int:
        """Items including home (MISSION_COUNT of a download)."""
        return len(self.items) + 1

    @property
    def route(self) -> bool:
        """Whether a mission is being flown."""
        return self.nav is not None

    def list_of(self, mission_type: int) -> list[MissionItem]:
        return self.fence if mission_type == M.MAV_MISSION_TYPE_FENCE else \
            self.rally if mission_type == M.MAV_MISSION_TYPE_RALLY else self.items

    def count_of(self, mission_type: int) -> int:
        """MISSION_COUNT of a download of that list."""
        return self.count if mission_type == M.MAV_MISSION_TYPE_MISSION \
            else len(self.list_of(mission_type))

    def item(self, seq: int, home: tuple[float, float, float],
             mission_type: int = M.MAV_MISSION_TYPE_MISSION) -> MissionItem | None:
        if mission_type != M.MAV_MISSION_TYPE_MISSION:
            lst = self.list_of(mission_type)
            return lst[seq] if 0 <= seq < len(lst) else None
        if seq == 0:
            return home_item(home)
        if 1 <= seq <= len(self.items):
            return self.items[seq - 1]
        return None

    def replace(self, items: Sequence[MissionItem], refused: dict[int, int] | None = None,
                mission_type: int = M.MAV_MISSION_TYPE_MISSION) -> None:
        """A new list; for the mission, flying state is reset."""
        if mission_type == M.MAV_MISSION_TYPE_FENCE:
            self.fence = list(items)
            self.breached = False
            return
        if mission_type == M.MAV_MISSION_TYPE_RALLY:
            self.rally = list(items)
            return
        self.items = list(items)
        self.refused = dict(refused or {})
        self.current = 0
        self.jumps = {}
        self.stop()

    def stop(self) -> None:
        """Stop flying it (the current item stays, to resume from)."""
        self.nav = None
        self.do_queue = []
        self.waiting = None
        self.complete = False

    def state(self, auto: bool) -> dict[str, Any]:
        """MISSION_CURRENT fields (total excludes home, as ArduPilot reports)."""
        if not self.items:
            st = STATE_NO_MISSION
        elif self.complete:
            st = STATE_COMPLETE
        elif auto and self.nav is not None:
            st = STATE_ACTIVE
        else:
            st = STATE_NOT_STARTED
        return {"seq": self.current, "total": len(self.items) if self.items else 65535,
                "mission_state": st, "mission_mode": 1 if auto else 0}

    def busy(self) -> bool:
        """Whether the runner has anything to do at this exchange."""
        return (self.upload is not None or self.nav is not None or bool(self.reached)
                or self.reported_current != self.current or bool(self.fence))


def point_of(v: MavVehicle, item: MissionItem, prev: tuple[float, float]
             ) -> tuple[float, float]:
    """An item's (lat, lon); x = y = 0: ``prev`` (ArduPilot: "here")."""
    return prev if item.here else (item.lat_deg, item.lon_deg)


def return_point(ctx: Context, v: MavVehicle) -> dict[str, Any]:
    """Where an RTL goes: the nearest rally point (at its altitude), else home."""
    row = v.row_values
    best: dict[str, Any] = {"lat_deg": v.home[0], "lon_deg": v.home[1]}
    if not v.mission.rally or row is None:
        return best
    lat, lon = float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]])
    best_d = math.hypot(*flat_ne(lat, lon, v.home[0], v.home[1]))
    for r in v.mission.rally:
        d = math.hypot(*flat_ne(lat, lon, r.lat_deg, r.lon_deg))
        if d < best_d:
            best_d = d
            best = {"lat_deg": r.lat_deg, "lon_deg": r.lon_deg}
            a = ctx.alt(v, r.frame, r.z)
            if a is not None:
                best[a[0]] = a[1]
    return best
