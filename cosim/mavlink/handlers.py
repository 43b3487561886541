"""Incoming MAVLink messages -> replies, vehicle state changes and commands
in the fixed-wing vocabulary (``cosim.guidance.commands``).

Every command is translated into the same mapping a scenario schedule
would hold (``{"goto": {...}}``, ``{"airspeed_mps": ...}``) and parsed by
``parse_command``, so MAVLink, the schedule and the swarm controller share
one vocabulary and one validation. ``handle`` never touches sockets: it
returns an ``Outcome`` (replies to send, commands for guidance).

Each COMMAND_LONG / COMMAND_INT gets exactly one COMMAND_ACK (a SET_MODE
message too, acknowledged as MAV_CMD_DO_SET_MODE like ArduPilot does).
Results:

- ACCEPTED: done (the command, if any, is in ``Outcome.commands``)
- DENIED: the parameters are invalid (out of range, unknown frame or message)
- FAILED: valid, but not possible now (mode needs a mission, disarm in flight,
  pre-arm check, no autopilot); a STATUSTEXT says why
- UNSUPPORTED: a command cosim does not implement

Positions: COMMAND_LONG carries degrees in param5/6 and an altitude relative
to home in param7 (ArduPilot's convention); COMMAND_INT carries degE7 in
x/y and the altitude frame in ``frame`` (global = MSL, relative = above
home, terrain = above ground). A position of (0, 0) or INT32_MAX means
"where the vehicle is". The local NED frame (SET_POSITION_TARGET_LOCAL_NED,
MAV_FRAME_LOCAL_NED) is relative to the vehicle's start, DESIGN.md 3.3.

Missions (ArduPlane's protocol, state in ``cosim.mavlink.mission``): upload
(MISSION_COUNT -> MISSION_REQUEST_INT, or MISSION_REQUEST once the client
answers with float MISSION_ITEMs -> ... -> MISSION_ACK; retried every
simulated second, cancelled after 8 s without progress), download, clear,
MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT. Item 0 is home. AUTO flies
the items from the current one as ONE ``waypoints`` command (see
``Handler._mission_route`` for how each item maps); progress is tracked
from the state rows (``mission_update``, once per exchange), which sends
MISSION_ITEM_REACHED and MISSION_CURRENT on a change (and 1 Hz as a
stream). MISSION_ITEM(_INT) with current=2 is a guided goto (GUIDED only),
current=3 an altitude change, both answered with a MISSION_ACK.

Disarmed vehicles keep their engine off: arming restores the cruise
airspeed, disarming sets throttle 0, and no other command carries a speed
while disarmed.
"""

from __future__ import annotations

import itertools
import logging
import math
import struct
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from cosim.geo import LocalFrame
from cosim.guidance.commands import Command, min_turn_radius_m, parse_command
from cosim.guidance.safety import Limits
from cosim.mavlink import adapter as mav
from cosim.mavlink.mission import (
    MAX_ITEMS,
    UPLOAD_RETRY_S,
    UPLOAD_TIMEOUT_S,
    MissionItem,
    RoutePoint,
    Upload,
)
from cosim.mavlink.params import PARAM_DEFS, PARAM_INDEX
from cosim.mavlink.vehicle import (
    DEFAULT_RATES_HZ,
    FORCE_MAGIC,
    STREAMABLE,
    MavVehicle,
    period_ticks,
)
from cosim.vehicles import get_class
from cosim.vehicles.fixed_wing.mavlink import PlaneMode  # until the personality owns the modes
from cosim.vehicles.spec import STATE_INDEX

log = logging.getLogger(__name__)

Reply = tuple[str, dict[str, Any]]
_S = STATE_INDEX
_INT32_MAX = 2 ** 31 - 1

#: the longest stream interval SET_MESSAGE_INTERVAL may ask for (us): an hour
MAX_INTERVAL_US = 3_600_000_000
#: modes a vehicle with an autopilot can be switched to
SETTABLE_MODES = (PlaneMode.GUIDED, PlaneMode.LOITER, PlaneMode.RTL, PlaneMode.TAKEOFF)

# MAVLink FTP (https://mavlink.io/en/services/ftp.html)
_FTP_ACK, _FTP_NAK = 128, 129
_FTP_ERR_FAIL, _FTP_ERR_INVALID_SESSION, _FTP_ERR_FILE_NOT_FOUND = 1, 4, 10
_FTP_PATH_OPS = {3, 4, 6, 8, 9, 10, 11, 12, 13, 14}  # list/open/create/remove/.../crc
_FTP_SESSION_OPS = {1, 5, 7, 15}  # terminate, read, write, burst read
_FTP_HEADER = struct.Struct("<HBBBBBBI")


@dataclass
class Outcome:
    """What handling one message produced, in order."""

    replies: list[Reply] = field(default_factory=list)
    commands: list[Command] = field(default_factory=list)


@dataclass(frozen=True)
class CommandRequest:
    """COMMAND_LONG and COMMAND_INT in one shape."""

    command: int
    p: tuple[float, float, float, float]  # param1..param4
    x: float  # param5 (deg) or x (degE7 for global frames)
    y: float
    z: float  # param7 or z
    frame: int  # COMMAND_LONG: MAV_FRAME_GLOBAL_RELATIVE_ALT
    is_int: bool

    @classmethod
    def of(cls, m: mav.Message) -> CommandRequest:
        f = m.fields
        ps = (float(f["param1"]), float(f["param2"]), float(f["param3"]), float(f["param4"]))
        if m.name == "COMMAND_INT":
            return cls(int(f["command"]), ps, float(f["x"]), float(f["y"]), float(f["z"]),
                       int(f["frame"]), True)
        return cls(int(f["command"]), ps, float(f["param5"]), float(f["param6"]),
                   float(f["param7"]), mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, False)

    def location(self) -> tuple[float, float] | None:
        """(lat_deg, lon_deg), or None for "where the vehicle is"."""
        x, y = self.x, self.y
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        if self.is_int:
            if _INT32_MAX in (int(x), int(y)) or (x == 0 and y == 0):
                return None
            return x / 1e7, y / 1e7
        if x == 0 and y == 0:
            return None
        return x, y


def _int(x: float) -> int | None:
    return int(round(x)) if math.isfinite(x) else None


def command_ack(m: mav.Message, command: int, result: int) -> Reply:
    """The COMMAND_ACK answering ``m``."""
    return ("COMMAND_ACK", {"command": command, "result": result, "progress": 0,
                            "result_param2": 0, "target_system": m.src_system,
                            "target_component": m.src_component})


#: STATUSTEXT carries 50 characters; a longer text goes in chunks sharing an id
_TEXT_CHARS = 50
_text_ids = itertools.count(1)


def _text(text: str, severity: int = mav.MAV_SEVERITY_WARNING) -> list[Reply]:
    """STATUSTEXT for ``text``: one message, or for a longer text chunks of 50
    characters with a common ``id`` and ``chunk_seq`` 0, 1, ... (MAVLink 2's
    long STATUSTEXT, which QGroundControl and MAVProxy put back together)."""
    text = text[:_TEXT_CHARS * 8]  # at most 400 characters
    if len(text) <= _TEXT_CHARS:
        return [("STATUSTEXT", {"severity": severity, "text": text})]
    ident = next(_text_ids) % 65535 + 1
    return [("STATUSTEXT", {"severity": severity, "text": text[i:i + _TEXT_CHARS], "id": ident,
                            "chunk_seq": i // _TEXT_CHARS})
            for i in range(0, len(text), _TEXT_CHARS)]


def _vocab(d: dict[str, Any]) -> Command | str:
    """A vocabulary mapping -> Command, or the problems as one string."""
    problems: list[str] = []
    cmd = parse_command(d, ("mavlink",), lambda p, msg: problems.append(
        f"{'.'.join(map(str, p[1:])) or 'command'}: {msg}"))
    if problems or cmd is None:
        return "; ".join(problems) or "invalid command"
    return cmd


class Handler:
    """Handles the messages addressed to one vehicle (one per endpoint)."""

    def __init__(self, counts: Counter[str], physics_hz: float) -> None:
        self.counts = counts
        self.physics_hz = physics_hz
        self._by_name: dict[str, Callable[[MavVehicle, mav.Message, int], Outcome]] = {
            "COMMAND_LONG": self._command,
            "COMMAND_INT": self._command,
            "SET_MODE": self._set_mode_msg,
            "PARAM_REQUEST_LIST": self._param_list,
            "PARAM_REQUEST_READ": self._param_read,
            "PARAM_SET": self._param_set,
            "FILE_TRANSFER_PROTOCOL": self._ftp,
            "SET_POSITION_TARGET_GLOBAL_INT": self._target_global,
            "SET_POSITION_TARGET_LOCAL_NED": self._target_local,
            "MISSION_COUNT": self._mission_count,
            "MISSION_ITEM_INT": self._mission_item,
            "MISSION_ITEM": self._mission_item,
            "MISSION_REQUEST_LIST": self._mission_request_list,
            "MISSION_REQUEST_INT": self._mission_request,
            "MISSION_REQUEST": self._mission_request,
            "MISSION_ACK": self._mission_ack_in,
            "MISSION_CLEAR_ALL": self._mission_clear,
            "MISSION_SET_CURRENT": self._mission_set_current_msg,
        }
        self.retry_ticks = max(1, round(UPLOAD_RETRY_S * physics_hz))
        self.timeout_ticks = max(1, round(UPLOAD_TIMEOUT_S * physics_hz))

    def handle(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        """Handle one message for vehicle ``v`` at ``tick`` (its row observed)."""
        fn = self._by_name.get(m.name)
        if fn is None:
            self.counts["ignored_messages"] += 1
            return Outcome()
        return fn(v, m, tick)

    # -- helpers -----------------------------------------------------------
    def _alt(self, v: MavVehicle, frame: int, z: float) -> tuple[str, float] | None:
        """An altitude in a global frame -> (vocabulary key, metres); None: bad frame."""
        if frame in (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT):
            return "alt_msl_m", z
        if frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            return "alt_msl_m", v.home[2] + z
        if frame in (mav.MAV_FRAME_GLOBAL_TERRAIN_ALT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT):
            return "alt_agl_m", z
        return None

    def _radius(self, v: MavVehicle, name: str = "WP_LOITER_RAD") -> tuple[float | None, bool]:
        """(radius_m or None for guidance's default, counter-clockwise)."""
        r = v.params[name]
        if name == "RTL_RADIUS" and r == 0:
            r = v.params["WP_LOITER_RAD"]
        return (abs(r) if r else None), r < 0

    def _speed_ok(self, v: MavVehicle, spd: float) -> str | None:
        lo, hi = v.params["AIRSPEED_MIN"], v.params["AIRSPEED_MAX"]
        if not lo <= spd <= hi:
            return f"speed {spd:g} m/s outside AIRSPEED_MIN..MAX {lo:g}..{hi:g}"
        return None

    def _loiter_here(self, v: MavVehicle) -> dict[str, Any]:
        radius, ccw = self._radius(v)
        lo: dict[str, Any] = {}
        if radius:
            lo["radius_m"] = radius
        if ccw:
            lo["direction"] = "ccw"
        return lo

    # -- modes ---------------------------------------------------------------
    def local_command(self, v: MavVehicle, cmd: Command) -> Command:
        """A command from inside cosim (a schedule item) for ``v``, applied to the
        vehicle's MAVLink state as a ground station's command would be: one
        that steers the vehicle (a nav command or a heading) puts it in GUIDED
        and so ends a mission flown in AUTO, as DO_REPOSITION does; settings
        (speed, altitude, limits) leave the mode alone. Returns the command
        for guidance, unchanged: one command path."""
        if v.spec.has_autopilot and (cmd.nav is not None or cmd.heading_deg is not None):
            v.mode = int(PlaneMode.GUIDED)
        return cmd

    def enter_mode(self, v: MavVehicle, mode: int, tick: int, out: Outcome) -> int:
        """Switch ``v`` to an ArduPlane mode; the result code (texts go to ``out``)."""
        if not v.spec.has_autopilot:
            if mode == v.mode:
                return mav.MAV_RESULT_ACCEPTED
            name = v.personality.mode_name(mode)
            out.replies.extend(_text(f"{name}: this vehicle has no autopilot"))
            return mav.MAV_RESULT_FAILED
        if mode == v.mode:
            return mav.MAV_RESULT_ACCEPTED
        row = v.row_or_raise()
        d: dict[str, Any]
        cw_override: bool | None = None
        if mode in (PlaneMode.GUIDED, PlaneMode.LOITER):
            d = {"loiter": self._loiter_here(v)}
        elif mode == PlaneMode.RTL:
            alt_cm = v.params["ALT_HOLD_RTL"]
            alt = float(row[_S["alt_msl_m"]]) if alt_cm < 0 else v.home[2] + alt_cm / 100.0
            goto: dict[str, Any] = {"lat_deg": v.home[0], "lon_deg": v.home[1], "alt_msl_m": alt}
            radius, ccw = self._radius(v, "RTL_RADIUS")
            if radius:
                goto["loiter_radius_m"] = radius
            cw_override = not ccw
            if v.armed:
                goto["airspeed_mps"] = v.params["AIRSPEED_CRUISE"]
            d = {"goto": goto}
        elif mode == PlaneMode.TAKEOFF:
            return self._takeoff(v, v.home[2] + v.params["TKOFF_ALT"], tick, out)
        elif mode == PlaneMode.AUTO:
            return self._auto(v, v.mission.current, out)
        elif mode == PlaneMode.MANUAL:
            out.replies.extend(_text("MANUAL: no pilot in the simulation"))
            return mav.MAV_RESULT_FAILED
        else:
            out.replies.extend(_text(f"{v.personality.mode_name(mode)} is not supported by "
                                     f"cosim"))
            return mav.MAV_RESULT_FAILED
        return self._switch_to(v, mode, d, out, v.personality.mode_name(mode),
                               mav.MAV_RESULT_FAILED, cw_override)

    def unsafe(self, v: MavVehicle, cmd: Command) -> str | None:
        """Why ``cmd`` would fly ``v`` into the ground or ask for a turn it
        cannot make (``cosim.guidance.safety``, the rule of every command
        path), counted; None: it may fly it."""
        row = v.row_values
        speed = row[_S["airspeed_mps"]] if row is not None and math.isfinite(
            row[_S["airspeed_mps"]]) else v.params["AIRSPEED_CRUISE"]
        problems = get_class(v.spec.vehicle_class).safety_problems(
            cmd, Limits(v.home[2], v.spec.min_alt_agl_m, speed, v.params["ROLL_LIMIT_DEG"]),
            "the vehicle")
        if not problems:
            return None
        self.counts["commands_unsafe"] += 1
        return "; ".join(problems)

    def _switch_to(self, v: MavVehicle, mode: int, d: dict[str, Any], out: Outcome, what: str,
                   refused: int = mav.MAV_RESULT_DENIED, cw: bool | None = None) -> int:
        """Turn vocabulary mapping ``d`` into a command for ``v`` in ``mode``; a
        mapping the vocabulary rejects is answered with a STATUSTEXT and
        ``refused``, a command that would crash (``unsafe``) with DENIED, both
        leaving the mode as it was."""
        cmd = _vocab(d)
        if isinstance(cmd, str):
            out.replies.extend(_text(f"{what}: {cmd}"))
            return refused
        problem = self.unsafe(v, cmd)
        if problem is not None:
            out.replies.extend(_text(f"{what}: {problem}"))
            return mav.MAV_RESULT_DENIED
        if cw is not None:
            cmd = replace(cmd, loiter_cw=cw)
        v.mode = int(mode)
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED

    def _takeoff(self, v: MavVehicle, alt_msl_m: float, tick: int, out: Outcome) -> int:
        if not v.spec.has_autopilot:
            out.replies.extend(_text("TAKEOFF: this vehicle has no autopilot"))
            return mav.MAV_RESULT_FAILED
        if not v.armed:
            out.replies.extend(_text("TAKEOFF: arm first"))
            return mav.MAV_RESULT_FAILED
        lo = self._loiter_here(v)
        if float(v.row_or_raise()[_S["alt_msl_m"]]) < alt_msl_m:  # takeoff climbs, never descends
            lo["alt_msl_m"] = alt_msl_m
        return self._switch_to(v, PlaneMode.TAKEOFF, {"loiter": lo}, out, "TAKEOFF")

    def _set_mode_msg(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        res = self._set_mode(v, int(m.fields["base_mode"]), float(m.fields["custom_mode"]),
                             tick, out)
        out.replies.append(command_ack(m, mav.MAV_CMD_DO_SET_MODE, res))
        return out

    def _set_mode(self, v: MavVehicle, base_mode: int | None, custom: float, tick: int,
                  out: Outcome) -> int:
        mode = _int(custom)
        if base_mode is None or not base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED \
                or mode is None:
            out.replies.extend(_text("set mode: use ArduPlane custom modes"))
            return mav.MAV_RESULT_DENIED
        return self.enter_mode(v, mode, tick, out)

    # -- commands ------------------------------------------------------------
    def _command(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        req = CommandRequest.of(m)
        fn = self._commands.get(req.command)
        if fn is None:
            self.counts["unsupported_commands"] += 1
            res = mav.MAV_RESULT_UNSUPPORTED
        else:
            res = fn(self, v, req, tick, out)
        if res != mav.MAV_RESULT_ACCEPTED:
            self.counts["commands_refused"] += 1
        out.replies.insert(self._ack_position(out, req), command_ack(m, req.command, res))
        return out

    @staticmethod
    def _ack_position(out: Outcome, req: CommandRequest) -> int:
        """The ACK goes after any STATUSTEXT but before requested messages."""
        return sum(1 for name, _ in out.replies if name == "STATUSTEXT")

    def _arm_disarm(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        want, force = _int(req.p[0]), _int(req.p[1]) == FORCE_MAGIC
        if want == 1:
            if v.armed:
                return mav.MAV_RESULT_ACCEPTED
            if v.params["ARMING_CHECK"] != 0 and not force and not v.prearm_ok():
                out.replies.extend(_text("PreArm: vehicle crashed or diverged"))
                return mav.MAV_RESULT_FAILED
            v.armed = True
            if v.spec.has_autopilot and v.mode in SETTABLE_MODES + (PlaneMode.AUTO,):
                cmd = _vocab({"airspeed_mps": v.params["AIRSPEED_CRUISE"]})
                if isinstance(cmd, Command):
                    out.commands.append(cmd)
            return mav.MAV_RESULT_ACCEPTED
        if want == 0:
            if not v.armed:
                return mav.MAV_RESULT_ACCEPTED
            if v.in_air() and not force:
                out.replies.extend(_text("Disarm refused in flight (param2=21196 forces)"))
                return mav.MAV_RESULT_FAILED
            v.armed = False
            if v.spec.has_autopilot:
                cmd = _vocab({"throttle": 0.0})
                if isinstance(cmd, Command):
                    out.commands.append(cmd)
            return mav.MAV_RESULT_ACCEPTED
        return mav.MAV_RESULT_DENIED

    def _do_set_mode(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        return self._set_mode(v, _int(req.p[0]), req.p[1], tick, out)

    def _rtl(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        return self.enter_mode(v, PlaneMode.RTL, tick, out)

    def _nav_takeoff(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        if math.isfinite(req.z) and req.z > 0:
            a = self._alt(v, req.frame, req.z)
            if a is None or a[0] != "alt_msl_m":
                out.replies.extend(_text("TAKEOFF: altitude frame not supported"))
                return mav.MAV_RESULT_DENIED
            alt = a[1]
        else:
            alt = v.home[2] + v.params["TKOFF_ALT"]
        return self._takeoff(v, alt, tick, out)

    def _change_speed(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        kind, spd, thr = _int(req.p[0]), req.p[1], req.p[2]
        if not v.spec.has_autopilot:
            out.replies.extend(_text("change speed: this vehicle has no autopilot"))
            return mav.MAV_RESULT_FAILED
        if kind not in (0, 1):  # airspeed; ground speed flown as airspeed (no wind)
            return mav.MAV_RESULT_DENIED
        if not v.armed:
            out.replies.extend(_text("change speed: disarmed"))
            return mav.MAV_RESULT_FAILED
        d: dict[str, Any]
        if math.isfinite(spd) and spd > 0:
            problem = self._speed_ok(v, spd)
            if problem:
                out.replies.extend(_text(problem))
                return mav.MAV_RESULT_DENIED
            d = {"airspeed_mps": spd}
        elif math.isfinite(thr) and 0 <= thr <= 100:
            d = {"throttle": thr / 100.0}
        else:
            return mav.MAV_RESULT_DENIED
        cmd = _vocab(d)
        if isinstance(cmd, str):
            return mav.MAV_RESULT_DENIED
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED

    def _position(self, v: MavVehicle, req: CommandRequest, out: Outcome
                  ) -> tuple[dict[str, Any], str | None] | None:
        """The horizontal point and altitude of a positional command (None: DENIED)."""
        loc = req.location()
        if loc is None:
            row = v.row_or_raise()
            loc = (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]))
        lat, lon = loc
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            out.replies.extend(_text(f"bad position {lat:g}, {lon:g}"))
            return None
        d: dict[str, Any] = {"lat_deg": lat, "lon_deg": lon}
        alt_key = None
        if math.isfinite(req.z):
            a = self._alt(v, req.frame, req.z)
            if a is None:
                out.replies.extend(_text(f"frame {req.frame} not supported"))
                return None
            alt_key = a[0]
            d[a[0]] = a[1]
        return d, alt_key

    def _reposition(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        if not v.spec.has_autopilot:
            out.replies.extend(_text("reposition: this vehicle has no autopilot"))
            return mav.MAV_RESULT_FAILED
        pos = self._position(v, req, out)
        if pos is None:
            return mav.MAV_RESULT_DENIED
        goto, _ = pos
        spd, flags, radius, direction = req.p
        if math.isfinite(spd) and spd > 0 and v.armed:
            problem = self._speed_ok(v, spd)
            if problem:
                out.replies.extend(_text(problem))
                return mav.MAV_RESULT_DENIED
            goto["airspeed_mps"] = spd
        default_r, default_ccw = self._radius(v)
        if math.isfinite(radius) and radius != 0:
            goto["loiter_radius_m"] = abs(radius)
            ccw = math.isfinite(direction) and direction != 0
        else:
            if default_r:
                goto["loiter_radius_m"] = default_r
            ccw = (math.isfinite(direction) and direction != 0) or default_ccw
        change = (_int(flags) or 0) & mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        if v.mode != PlaneMode.GUIDED and not change:
            out.replies.extend(_text("reposition: switch to GUIDED first"))
            return mav.MAV_RESULT_FAILED
        return self._switch_to(v, PlaneMode.GUIDED, {"goto": goto}, out, "reposition",
                               cw=not ccw)

    def _loiter_unlim(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        if not v.spec.has_autopilot:
            out.replies.extend(_text("loiter: this vehicle has no autopilot"))
            return mav.MAV_RESULT_FAILED
        radius = req.p[2]
        lo = self._loiter_here(v)
        if math.isfinite(radius) and radius != 0:  # ArduPilot: negative = counter-clockwise
            lo["radius_m"] = abs(radius)
            lo["direction"] = "ccw" if radius < 0 else "cw"
        z = req.z if math.isfinite(req.z) and req.z != 0 else math.nan
        pos = self._position(v, replace(req, z=z), out)
        if pos is None:
            return mav.MAV_RESULT_DENIED
        point, alt_key = pos
        if req.location() is not None:
            lo["center"] = {"lat_deg": point["lat_deg"], "lon_deg": point["lon_deg"]}
        if alt_key is not None:
            lo[alt_key] = point[alt_key]
        return self._switch_to(v, PlaneMode.LOITER, {"loiter": lo}, out, "loiter")

    def _send_message(self, v: MavVehicle, name: str | None, tick: int, out: Outcome) -> int:
        if name not in STREAMABLE:
            return mav.MAV_RESULT_DENIED
        out.replies.append((name, v.fields(name, tick)))
        return mav.MAV_RESULT_ACCEPTED

    def _request_message(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome
                         ) -> int:
        mid = _int(req.p[0])
        return self._send_message(v, None if mid is None else mav.msg_name(mid), tick, out)

    def _request_capabilities(self, v: MavVehicle, req: CommandRequest, tick: int,
                              out: Outcome) -> int:
        if _int(req.p[0]) != 1:
            return mav.MAV_RESULT_ACCEPTED  # nothing requested
        return self._send_message(v, "AUTOPILOT_VERSION", tick, out)

    def _get_home(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        return self._send_message(v, "HOME_POSITION", tick, out)

    def _set_interval(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        mid, interval = _int(req.p[0]), req.p[1]
        name = None if mid is None else mav.msg_name(mid)
        if name not in STREAMABLE or not math.isfinite(interval) \
                or not -1 <= interval <= MAX_INTERVAL_US:
            return mav.MAV_RESULT_DENIED
        hz = self.physics_hz
        if interval == -1:
            period = None
        elif interval == 0:
            period = period_ticks(DEFAULT_RATES_HZ.get(name, 0.0), hz)
        else:
            period = max(1, round(interval * 1e-6 * hz))
        v.set_period(name, period, tick)
        return mav.MAV_RESULT_ACCEPTED

    def _get_interval(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        mid = _int(req.p[0])
        name = None if mid is None else mav.msg_name(mid)
        if mid is None or not 0 <= mid <= 0xFFFF:  # MESSAGE_INTERVAL.message_id: uint16
            return mav.MAV_RESULT_DENIED
        if name not in STREAMABLE:
            us = 0  # not available
        else:
            p = v.period[name]
            us = -1 if p is None else round(p * 1e6 / self.physics_hz)
        out.replies.append(("MESSAGE_INTERVAL", {"message_id": mid, "interval_us": us}))
        return mav.MAV_RESULT_ACCEPTED

    def _do_set_mission_current(self, v: MavVehicle, req: CommandRequest, tick: int,
                                out: Outcome) -> int:
        seq = _int(req.p[0])
        if seq is None or seq == -1:  # -1: leave the current item as it is
            return mav.MAV_RESULT_ACCEPTED
        return self.set_mission_current(v, seq, out)

    _commands: dict[int, Callable[[Handler, MavVehicle, CommandRequest, int, Outcome], int]] = {
        mav.MAV_CMD_COMPONENT_ARM_DISARM: _arm_disarm,
        mav.MAV_CMD_DO_SET_MODE: _do_set_mode,
        mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: _rtl,
        mav.MAV_CMD_NAV_TAKEOFF: _nav_takeoff,
        mav.MAV_CMD_DO_CHANGE_SPEED: _change_speed,
        mav.MAV_CMD_DO_REPOSITION: _reposition,
        mav.MAV_CMD_NAV_LOITER_UNLIM: _loiter_unlim,
        mav.MAV_CMD_REQUEST_MESSAGE: _request_message,
        mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _request_capabilities,
        mav.MAV_CMD_GET_HOME_POSITION: _get_home,
        mav.MAV_CMD_SET_MESSAGE_INTERVAL: _set_interval,
        mav.MAV_CMD_GET_MESSAGE_INTERVAL: _get_interval,
        mav.MAV_CMD_DO_SET_MISSION_CURRENT: _do_set_mission_current,
    }

    # -- position targets (no ACK, as in ArduPilot) ------------------------------
    def _target_ok(self, v: MavVehicle) -> bool:
        if not v.spec.has_autopilot or v.mode != PlaneMode.GUIDED:
            self.counts["position_targets_ignored"] += 1  # ArduPlane: GUIDED only
            return False
        return True

    def _target_cmd(self, v: MavVehicle, d: dict[str, Any]) -> Outcome:
        cmd = _vocab(d)
        if isinstance(cmd, str):
            self.counts["position_targets_invalid"] += 1
            log.debug("position target rejected: %s", cmd)
            return Outcome()
        problem = self.unsafe(v, cmd)
        if problem is not None:  # no ACK for position targets: a STATUSTEXT says why
            self.counts["position_targets_invalid"] += 1
            return Outcome(replies=_text(f"position target: {problem}"))
        return Outcome(commands=[cmd])

    @staticmethod
    def _mask(type_mask: int) -> tuple[bool, bool] | None:
        """(horizontal position given, altitude given); None: unusable mask."""
        xy = type_mask & (mav.POSITION_TARGET_TYPEMASK_X_IGNORE
                          | mav.POSITION_TARGET_TYPEMASK_Y_IGNORE)
        if xy not in (0, mav.POSITION_TARGET_TYPEMASK_X_IGNORE
                      | mav.POSITION_TARGET_TYPEMASK_Y_IGNORE):
            return None
        has_xy = xy == 0
        has_z = not type_mask & mav.POSITION_TARGET_TYPEMASK_Z_IGNORE
        return (has_xy, has_z) if (has_xy or has_z) else None

    def _target_global(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        if not self._target_ok(v):
            return Outcome()
        f = m.fields
        mask = self._mask(int(f["type_mask"]))
        alt = self._alt(v, int(f["coordinate_frame"]), float(f["alt"]))
        if mask is None or alt is None:
            self.counts["position_targets_unsupported"] += 1
            return Outcome()
        has_xy, has_z = mask
        d: dict[str, Any] = {alt[0]: alt[1]} if has_z else {}
        if has_xy:
            d.update(lat_deg=int(f["lat_int"]) / 1e7, lon_deg=int(f["lon_int"]) / 1e7)
            return self._target_cmd(v, {"goto": d})
        return self._target_cmd(v, d)

    def _target_local(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        if not self._target_ok(v):
            return Outcome()
        f = m.fields
        mask = self._mask(int(f["type_mask"]))
        frame = int(f["coordinate_frame"])
        x, y, z = float(f["x"]), float(f["y"]), float(f["z"])
        if mask is None or frame not in (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED,
                                         mav.MAV_FRAME_BODY_OFFSET_NED) \
                or not all(map(math.isfinite, (x, y, z))):
            self.counts["position_targets_unsupported"] += 1
            return Outcome()
        has_xy, has_z = mask
        row = v.row_or_raise()
        if frame == mav.MAV_FRAME_LOCAL_NED:  # relative to the vehicle's start
            alt = v.spec.start_alt_msl_m - z
            if not has_xy:
                return self._target_cmd(v, {"alt_msl_m": alt})
            goto: dict[str, Any] = {"frame": "start", "north_m": x, "east_m": y}
        else:  # offsets from where the vehicle is now
            lat0, lon0 = float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]])
            alt0 = float(row[_S["alt_msl_m"]])
            alt = alt0 - z
            if not has_xy:
                return self._target_cmd(v, {"alt_msl_m": alt})
            north, east = x, y
            if frame == mav.MAV_FRAME_BODY_OFFSET_NED:  # x forward, y right
                psi = math.radians(float(row[_S["yaw_deg"]]))
                north = x * math.cos(psi) - y * math.sin(psi)
                east = x * math.sin(psi) + y * math.cos(psi)
            lat, lon = LocalFrame(lat0, lon0, alt0).place(north, east, alt0)
            goto = {"lat_deg": float(lat), "lon_deg": float(lon)}
        if has_z:
            goto["alt_msl_m"] = alt
        return self._target_cmd(v, {"goto": goto})

    # -- parameters ------------------------------------------------------------
    def param_value(self, v: MavVehicle, name: str) -> Reply:
        """The PARAM_VALUE of one parameter (to announce a change)."""
        return self._param_value(v, PARAM_INDEX[name])

    def _param_value(self, v: MavVehicle, index: int) -> Reply:
        p = PARAM_DEFS[index]
        return ("PARAM_VALUE", {"param_id": p.name, "param_value": v.params.values[index],
                                "param_type": p.mav_type, "param_count": len(PARAM_DEFS),
                                "param_index": index})

    def _param_list(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        return Outcome(replies=[self._param_value(v, i) for i in range(len(PARAM_DEFS))])

    def _param_read(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        idx = int(m.fields["param_index"])
        if idx < 0:
            idx = PARAM_INDEX.get(str(m.fields["param_id"]).strip("\0 "), -1)
        if not 0 <= idx < len(PARAM_DEFS):
            self.counts["param_unknown"] += 1
            return Outcome()
        return Outcome(replies=[self._param_value(v, idx)])

    def _param_set(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        name = str(m.fields["param_id"]).strip("\0 ")
        idx = PARAM_INDEX.get(name)
        if idx is None:
            self.counts["param_unknown"] += 1
            return Outcome()
        value = float(m.fields["param_value"])
        out = Outcome()
        problem = v.params.check(name, value) or self._param_unsafe(v, name, value) \
            or v.params.set(name, value)
        if problem:
            self.counts["param_rejected"] += 1
            out.replies.extend(_text(f"{name}: {problem}"))
        else:
            d: dict[str, Any] | None = None
            if name == "ROLL_LIMIT_DEG":
                d = {"bank_limit_deg": v.params[name]}
            elif name == "STALL_PREVENTION":
                d = {"stall_protection": bool(v.params[name])}
            if d is not None and v.spec.has_autopilot:
                cmd = _vocab(d)
                if isinstance(cmd, Command):
                    out.commands.append(cmd)
        out.replies.append(self._param_value(v, idx))  # the value now in force
        return out

    def _param_unsafe(self, v: MavVehicle, name: str, value: float) -> str | None:
        """Why a parameter value would make a later command crash the vehicle
        (the RTL and takeoff heights, the loiter radii), counted; None: fine."""
        floor = v.spec.min_alt_agl_m
        problem = None
        if name == "ALT_HOLD_RTL" and value != -1 and value / 100.0 < floor:
            problem = f"RTL at {value / 100:g} m above home: at least {floor:g} m (or -1)"
        elif name == "TKOFF_ALT" and value < floor:
            problem = f"takeoff to {value:g} m above home: at least {floor:g} m"
        elif name in ("WP_LOITER_RAD", "RTL_RADIUS") and value != 0:
            r_min = min_turn_radius_m(v.params["AIRSPEED_CRUISE"], v.params["ROLL_LIMIT_DEG"])
            if abs(value) < r_min:
                problem = (f"radius {abs(value):g} m is below the minimum turn radius "
                           f"({r_min:.0f} m at AIRSPEED_CRUISE and ROLL_LIMIT_DEG; or 0)")
        if problem is not None:
            self.counts["commands_unsafe"] += 1
        return problem

    def _item_too_low(self, v: MavVehicle, item: MissionItem) -> str | None:
        """Why a mission item's altitude is below the class minimum above the
        ground (the rule of ``unsafe``); None: fine or no altitude."""
        if item.command not in (mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_LOITER_UNLIM,
                                mav.MAV_CMD_NAV_TAKEOFF):
            return None
        alt = self._alt(v, item.frame, item.z)
        if alt is None:
            return None
        agl = alt[1] if alt[0] == "alt_agl_m" else alt[1] - v.home[2]
        if agl >= v.spec.min_alt_agl_m - 1e-6:
            return None
        self.counts["commands_unsafe"] += 1
        return (f"at {agl:.0f} m above the ground refused (at least "
                f"{v.spec.min_alt_agl_m:g} m)")

    # -- FTP: always NAK, so ground stations fall back at once --------------------
    def _ftp(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        payload = bytes(int(b) & 0xFF for b in m.fields["payload"])
        if len(payload) < _FTP_HEADER.size:
            return Outcome()
        seq, session, opcode = _FTP_HEADER.unpack_from(payload)[:3]
        if opcode in (_FTP_ACK, _FTP_NAK):  # a response, not a request: never answer
            return Outcome()
        err = (_FTP_ERR_FILE_NOT_FOUND if opcode in _FTP_PATH_OPS else
               _FTP_ERR_INVALID_SESSION if opcode in _FTP_SESSION_OPS else _FTP_ERR_FAIL)
        head = _FTP_HEADER.pack((seq + 1) % 65536, session, _FTP_NAK, 1, opcode, 0, 0, 0)
        body = list(head + bytes([err]))
        self.counts["ftp_naks"] += 1
        return Outcome(replies=[("FILE_TRANSFER_PROTOCOL", {
            "target_network": 0, "target_system": m.src_system,
            "target_component": m.src_component, "payload": body + [0] * (251 - len(body))})])

    # -- missions (ArduPlane's mission protocol; cosim.mavlink.mission) ------------
    @staticmethod
    def _mission_ack(m: mav.Message, result: int, to: tuple[int, int] | None = None,
                     mission_type: int = mav.MAV_MISSION_TYPE_MISSION) -> Reply:
        ts, tc = to if to is not None else (m.src_system, m.src_component)
        return ("MISSION_ACK", {"target_system": ts, "target_component": tc, "type": result,
                                "mission_type": mission_type})

    @staticmethod
    def _mission_item_request(up: Upload) -> Reply:
        return ("MISSION_REQUEST_INT" if up.use_int else "MISSION_REQUEST", {
            "target_system": up.partner[0], "target_component": up.partner[1],
            "seq": up.next_seq, "mission_type": mav.MAV_MISSION_TYPE_MISSION})

    def _mission_count(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        mtype, count = int(m.fields["mission_type"]), int(m.fields["count"])
        partner = (m.src_system, m.src_component)
        ms = v.mission
        if mtype != mav.MAV_MISSION_TYPE_MISSION:  # no fence or rally points in cosim
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_UNSUPPORTED,
                                                 mission_type=mtype))
            return out
        if ms.upload is not None and ms.upload.partner != partner:
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_DENIED))
            return out
        if count - 1 > MAX_ITEMS:
            ms.upload = None
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_NO_SPACE))
            return out
        if count <= 1:  # nothing (or home only): an empty mission
            ms.upload = None
            self._mission_replaced(v, [], out)
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ACCEPTED))
            return out
        ms.upload = Upload(partner, count, last_request_tick=tick, last_progress_tick=tick)
        out.replies.append(self._mission_item_request(ms.upload))
        return out

    def _mission_item(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        current = int(m.fields["current"])
        if current == 2:
            return self._guided_item(v, m)
        if current == 3:
            return self._guided_alt(v, m)
        out = Outcome()
        mtype = int(m.fields["mission_type"])
        up = v.mission.upload
        if up is None or up.partner != (m.src_system, m.src_component) \
                or mtype != mav.MAV_MISSION_TYPE_MISSION:
            self.counts["mission_unexpected"] += 1
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ERROR, mission_type=mtype))
            return out
        item = MissionItem.of(m)
        if item.seq != up.next_seq:
            if item.seq == up.next_seq - 1:  # a repeat of the last one: ask again
                out.replies.append(self._mission_item_request(up))
            else:  # ArduPilot: say so, keep the upload open (it retries or times out)
                out.replies.append(self._mission_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE))
            return out
        up.use_int = m.name == "MISSION_ITEM_INT"
        if item.seq > 0:  # item 0 is home: its contents are ignored
            result = item.check()
            why = "refused"
            if result == mav.MAV_MISSION_ACCEPTED:
                low = self._item_too_low(v, item)
                if low is not None:
                    result, why = mav.MAV_MISSION_INVALID_PARAM7, low
            if result != mav.MAV_MISSION_ACCEPTED:
                v.mission.upload = None  # the mission on board is unchanged
                self.counts["mission_upload_errors"] += 1
                out.replies.extend(_text(f"Mission item {item.seq}: "
                                         f"{mav.command_name(item.command)} {why}"))
                out.replies.append(self._mission_ack(m, result))
                return out
            up.received.append(item)
        up.next_seq += 1
        up.last_progress_tick = up.last_request_tick = tick
        if up.next_seq < up.count:
            out.replies.append(self._mission_item_request(up))
            return out
        v.mission.upload = None
        self.counts["mission_uploads"] += 1
        self._mission_replaced(v, up.received, out)
        out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ACCEPTED))
        return out

    def _mission_replaced(self, v: MavVehicle, items: list[MissionItem], out: Outcome) -> None:
        """Store a new mission; a vehicle in AUTO restarts it from item 1 (or, with
        nothing left to fly, loiters where it is, in LOITER)."""
        v.mission.replace(items)
        if v.mode != PlaneMode.AUTO:
            return
        if self._auto(v, 1, out) != mav.MAV_RESULT_ACCEPTED:
            self.enter_mode(v, PlaneMode.LOITER, 0, out)

    def _mission_request_list(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        mtype = int(m.fields["mission_type"])
        count = v.mission.count if mtype == mav.MAV_MISSION_TYPE_MISSION else 0
        return Outcome(replies=[("MISSION_COUNT", {
            "target_system": m.src_system, "target_component": m.src_component,
            "count": count, "mission_type": mtype})])

    def _mission_request(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        mtype = int(m.fields["mission_type"])
        item = v.mission.item(int(m.fields["seq"]), v.home) \
            if mtype == mav.MAV_MISSION_TYPE_MISSION else None
        if item is None:
            return Outcome(replies=[self._mission_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE,
                                                      mission_type=mtype)])
        name = "MISSION_ITEM_INT" if m.name == "MISSION_REQUEST_INT" else "MISSION_ITEM"
        return Outcome(replies=[(name, item.fields(
            name == "MISSION_ITEM_INT", (m.src_system, m.src_component),
            item.seq == v.mission.current and item.seq > 0))])

    def _mission_ack_in(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        up = v.mission.upload
        if up is not None and up.partner == (m.src_system, m.src_component) \
                and int(m.fields["type"]) != mav.MAV_MISSION_ACCEPTED:
            v.mission.upload = None  # the client cancelled its upload
            self.counts["mission_upload_errors"] += 1
        elif int(m.fields["type"]) == mav.MAV_MISSION_ACCEPTED:
            self.counts["mission_downloads"] += 1
        return Outcome()

    def _mission_clear(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        mtype = int(m.fields["mission_type"])
        if mtype not in (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_ALL):
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_UNSUPPORTED,
                                                 mission_type=mtype))
            return out
        v.mission.upload = None
        self._mission_replaced(v, [], out)
        out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ACCEPTED, mission_type=mtype))
        return out

    def _mission_set_current_msg(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        if self.set_mission_current(v, int(m.fields["seq"]), out) != mav.MAV_RESULT_ACCEPTED:
            self.counts["commands_refused"] += 1
        return out

    def set_mission_current(self, v: MavVehicle, seq: int, out: Outcome) -> int:
        """Make ``seq`` the current item; in AUTO the vehicle flies on from it.
        MISSION_CURRENT follows at the end of the exchange."""
        ms = v.mission
        if not 1 <= seq < ms.count:
            out.replies.extend(_text(f"Mission item {seq} does not exist"))
            return mav.MAV_RESULT_DENIED
        if v.mode == PlaneMode.AUTO:
            return self._auto(v, seq, out)
        ms.stop()
        ms.current = seq
        return mav.MAV_RESULT_ACCEPTED

    def _auto(self, v: MavVehicle, start: int, out: Outcome) -> int:
        """Switch to AUTO (or stay in it) flying the mission from item ``start``
        (0: from item 1) as one ``waypoints`` command."""
        ms = v.mission
        if not ms.items:
            out.replies.extend(_text("AUTO: no mission loaded"))
            return mav.MAV_RESULT_FAILED
        built = self._mission_route(v, max(start, 1))
        if isinstance(built, str):
            out.replies.extend(_text(f"AUTO: {built}"))
            return mav.MAV_RESULT_FAILED
        cmd, route = built
        problem = self.unsafe(v, cmd)
        if problem is not None:
            out.replies.extend(_text(f"AUTO: {problem}"))
            return mav.MAV_RESULT_DENIED
        row = v.row_or_raise()
        ms.fly(route, (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]])))
        v.mode = int(PlaneMode.AUTO)
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED

    def _mission_route(self, v: MavVehicle, start: int
                       ) -> tuple[Command, list[RoutePoint]] | str:
        """The ``waypoints`` command flying items ``start``.. and the route it flies.

        NAV_WAYPOINT: a point; NAV_LOITER_UNLIM: the last point, loitered around
        (its radius and direction); NAV_RETURN_TO_LAUNCH: home at the RTL
        altitude, loitered around (RTL_RADIUS); items after those two are never
        reached, as in ArduPlane. DO_CHANGE_SPEED sets the airspeed of the
        following points (before one: AIRSPEED_CRUISE; none while disarmed).
        NAV_TAKEOFF: skipped by a vehicle in the air (cosim's vehicles start
        flying); on the ground, a point 1 km ahead on its heading at the
        takeoff altitude. The loiter at the end of a mission without one is
        around its last point (``waypoints`` always ends in a loiter).
        """
        row = v.row_or_raise()
        here = (float(row[_S["lat_deg"]]), float(row[_S["lon_deg"]]))
        prev = here
        speed = v.params["AIRSPEED_CRUISE"] if v.armed else None
        radius, ccw = self._radius(v)
        points: list[dict[str, Any]] = []
        route: list[RoutePoint] = []
        for it in v.mission.items[start - 1:]:
            c = it.command
            if c == mav.MAV_CMD_DO_CHANGE_SPEED:
                if it.param2 > 0 and v.armed:
                    problem = self._speed_ok(v, it.param2)
                    if problem:
                        return f"item {it.seq}: {problem}"
                    speed = it.param2
                continue
            end = False
            p: dict[str, Any]
            if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                alt_cm = v.params["ALT_HOLD_RTL"]
                alt = float(row[_S["alt_msl_m"]]) if alt_cm < 0 else v.home[2] + alt_cm / 100.0
                p = {"lat_deg": v.home[0], "lon_deg": v.home[1], "alt_msl_m": alt}
                radius, ccw = self._radius(v, "RTL_RADIUS")
                end = True
            else:
                a = self._alt(v, it.frame, it.z)
                if a is None:
                    return f"item {it.seq}: frame {it.frame} not supported"
                if c == mav.MAV_CMD_NAV_TAKEOFF:
                    if v.in_air():
                        continue
                    psi = math.radians(float(row[_S["yaw_deg"]]))
                    lat, lon = LocalFrame(here[0], here[1], v.home[2]).place(
                        1000.0 * math.cos(psi), 1000.0 * math.sin(psi), v.home[2])
                    p = {"lat_deg": float(lat), "lon_deg": float(lon)}
                elif it.x == 0 and it.y == 0:  # ArduPilot: "here" (the previous point)
                    p = {"lat_deg": prev[0], "lon_deg": prev[1]}
                else:
                    p = {"lat_deg": it.lat_deg, "lon_deg": it.lon_deg}
                p[a[0]] = a[1]
                if c == mav.MAV_CMD_NAV_LOITER_UNLIM:
                    if it.param3 != 0:  # negative: counter-clockwise
                        radius, ccw = abs(it.param3), it.param3 < 0
                    end = True
            if speed is not None:
                p["airspeed_mps"] = speed
            points.append(p)
            prev = (p["lat_deg"], p["lon_deg"])
            route.append(RoutePoint(it.seq, p["lat_deg"], p["lon_deg"]))
            if end:
                break
        if not points:
            return "no navigation items left in the mission"
        wp: dict[str, Any] = {"points": points}
        if radius:
            wp["loiter_radius_m"] = radius
        cmd = _vocab({"waypoints": wp})
        if isinstance(cmd, str):
            return cmd
        last = route[-1]
        route[-1] = RoutePoint(last.seq, last.lat_deg, last.lon_deg, True, radius)
        return replace(cmd, loiter_cw=not ccw), route

    def mission_update(self, v: MavVehicle, tick: int) -> list[Reply]:
        """Once per exchange after the messages: upload retries and timeout, progress
        along the mission in AUTO (MISSION_ITEM_REACHED) and MISSION_CURRENT on a
        change of the current item."""
        ms = v.mission
        out: list[Reply] = []
        up = ms.upload
        if up is not None and tick - up.last_request_tick >= self.retry_ticks:
            if tick - up.last_progress_tick >= self.timeout_ticks:
                ms.upload = None
                self.counts["mission_upload_timeouts"] += 1
                out.append(("MISSION_ACK", {
                    "target_system": up.partner[0], "target_component": up.partner[1],
                    "type": mav.MAV_MISSION_OPERATION_CANCELLED,
                    "mission_type": mav.MAV_MISSION_TYPE_MISSION}))
            else:
                up.last_request_tick = tick
                self.counts["mission_rerequests"] += 1
                out.append(self._mission_item_request(up))
        if v.mode == PlaneMode.AUTO and v.row_values is not None:
            ms.track(v.row_values, _S)
        elif ms.route:
            ms.stop()  # left AUTO: the current item stays, to resume from
        for seq in ms.reached:
            self.counts["mission_items_reached"] += 1
            out.append(("MISSION_ITEM_REACHED", {"seq": seq}))
        ms.reached.clear()
        if ms.reported_current != ms.current and v.period.get("MISSION_CURRENT") is not None:
            out.append(("MISSION_CURRENT", v.fields("MISSION_CURRENT", tick)))
        return out

    def _guided_item(self, v: MavVehicle, m: mav.Message) -> Outcome:
        """MISSION_ITEM(_INT) with current=2: "fly to here" in GUIDED (MAVProxy's
        and older stations' guided goto), answered with a MISSION_ACK."""
        out = Outcome()
        item = MissionItem.of(m)
        if not v.spec.has_autopilot or v.mode != PlaneMode.GUIDED:
            out.replies.extend(_text("guided goto: switch to GUIDED first"))
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ERROR))
            self.counts["commands_refused"] += 1
            return out
        result = item.check() if item.command == mav.MAV_CMD_NAV_WAYPOINT \
            else mav.MAV_MISSION_UNSUPPORTED
        alt = self._alt(v, item.frame, item.z)
        if result != mav.MAV_MISSION_ACCEPTED or alt is None:
            out.replies.append(self._mission_ack(m, result if result != mav.MAV_MISSION_ACCEPTED
                                                 else mav.MAV_MISSION_UNSUPPORTED_FRAME))
            self.counts["commands_refused"] += 1
            return out
        goto: dict[str, Any] = {"lat_deg": item.lat_deg, "lon_deg": item.lon_deg, alt[0]: alt[1]}
        radius, ccw = self._radius(v)
        if radius:
            goto["loiter_radius_m"] = radius
        return self._guided_answer(v, m, {"goto": goto}, "guided goto", out, cw=not ccw)

    def _guided_answer(self, v: MavVehicle, m: mav.Message, d: dict[str, Any], what: str,
                       out: Outcome, cw: bool | None = None) -> Outcome:
        """A guided MISSION_ITEM's command from vocabulary mapping ``d``, answered
        with a MISSION_ACK: ERROR if the vocabulary refuses it, INVALID_PARAM7 if
        it would crash (``unsafe``), else ACCEPTED."""
        cmd = _vocab(d)
        problem = cmd if isinstance(cmd, str) else self.unsafe(v, cmd)
        if problem is not None or isinstance(cmd, str):
            out.replies.extend(_text(f"{what}: {problem}"))
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ERROR if isinstance(cmd, str)
                                                 else mav.MAV_MISSION_INVALID_PARAM7))
            self.counts["commands_refused"] += 1
            return out
        out.commands.append(cmd if cw is None else replace(cmd, loiter_cw=cw))
        out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ACCEPTED))
        return out

    def _guided_alt(self, v: MavVehicle, m: mav.Message) -> Outcome:
        """MISSION_ITEM(_INT) with current=3: change the altitude (ArduPlane, GUIDED
        and the other autopilot modes)."""
        out = Outcome()
        item = MissionItem.of(m)
        alt = self._alt(v, item.frame, item.z)
        if not v.spec.has_autopilot or v.mode not in SETTABLE_MODES + (PlaneMode.AUTO,) \
                or alt is None:
            out.replies.append(self._mission_ack(m, mav.MAV_MISSION_ERROR))
            self.counts["commands_refused"] += 1
            return out
        return self._guided_answer(v, m, {alt[0]: alt[1]}, "change altitude", out)
