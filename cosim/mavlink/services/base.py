"""What every MAVLink service shares: the shape of an answer (``Outcome``),
COMMAND_LONG and COMMAND_INT in one shape (``CommandRequest``), the replies
every service sends (COMMAND_ACK, MISSION_ACK, chunked STATUSTEXT) and the
``Context`` services and personalities work in (counters, the physics rate,
altitude frames, the safety rule, a mode switch with its command)."""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from cosim.guidance.commands import Command, parse_command
from cosim.mavlink import adapter as mav

if TYPE_CHECKING:
    from cosim.mavlink.vehicle import MavVehicle

Reply = tuple[str, dict[str, Any]]
INT32_MAX = 2 ** 31 - 1


@dataclass
class Outcome:
    """What handling one message produced, in order: replies to send,
    commands for guidance and run events (kind, fields)."""

    replies: list[Reply] = field(default_factory=list)
    commands: list[Command] = field(default_factory=list)
    events: list[tuple[str, dict[str, Any]]] = field(default_factory=list)


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
            if INT32_MAX in (int(x), int(y)) or (x == 0 and y == 0):
                return None
            return x / 1e7, y / 1e7
        if x == 0 and y == 0:
            return None
        return x, y


def as_int(x: float) -> int | None:
    """A float parameter as the integer it carries (None: not finite)."""
    return int(round(x)) if math.isfinite(x) else None


def command_ack(m: mav.Message, command: int, result: int) -> Reply:
    """The COMMAND_ACK answering ``m``."""
    return ("COMMAND_ACK", {"command": command, "result": result, "progress": 0,
                            "result_param2": 0, "target_system": m.src_system,
                            "target_component": m.src_component})


def mission_ack(m: mav.Message, result: int, to: tuple[int, int] | None = None,
                mission_type: int = mav.MAV_MISSION_TYPE_MISSION) -> Reply:
    """The MISSION_ACK answering ``m`` (or sent to ``to``)."""
    ts, tc = to if to is not None else (m.src_system, m.src_component)
    return ("MISSION_ACK", {"target_system": ts, "target_component": tc, "type": result,
                            "mission_type": mission_type})


#: STATUSTEXT carries 50 characters; a longer text goes in chunks sharing an id
_TEXT_CHARS = 50
_text_ids = itertools.count(1)


def text(message: str, severity: int = mav.MAV_SEVERITY_WARNING) -> list[Reply]:
    """STATUSTEXT for ``message``: one, or for a longer text chunks of 50
    characters with a common ``id`` and ``chunk_seq`` 0, 1, ... (MAVLink 2's
    long STATUSTEXT, which QGroundControl and MAVProxy put back together)."""
    message = message[:_TEXT_CHARS * 8]  # at most 400 characters
    if len(message) <= _TEXT_CHARS:
        return [("STATUSTEXT", {"severity": severity, "text": message})]
    ident = next(_text_ids) % 65535 + 1
    return [("STATUSTEXT", {"severity": severity, "text": message[i:i + _TEXT_CHARS],
                            "id": ident, "chunk_seq": i // _TEXT_CHARS})
            for i in range(0, len(message), _TEXT_CHARS)]


def vocab(d: dict[str, Any]) -> Command | str:
    """A vocabulary mapping (what a scenario schedule would hold) -> Command,
    or the problems as one string: MAVLink, the schedule and the swarm share
    one vocabulary and one validation."""
    problems: list[str] = []
    cmd = parse_command(d, ("mavlink",), lambda p, msg: problems.append(
        f"{'.'.join(map(str, p[1:])) or 'command'}: {msg}"))
    if problems or cmd is None:
        return "; ".join(problems) or "invalid command"
    return cmd


class Context:
    """What the services of one endpoint share, handed to each vehicle's
    personality with every call: the counters, the physics rate and the
    helpers every class's commands need."""

    def __init__(self, counts: Counter[str], physics_hz: float) -> None:
        self.counts = counts
        self.physics_hz = physics_hz
        #: the tick of the exchange being handled (set by the handler)
        self.tick = 0

    @staticmethod
    def alt(v: MavVehicle, frame: int, z: float) -> tuple[str, float] | None:
        """An altitude in a global frame -> (vocabulary key, metres); None: a
        frame without an altitude cosim knows."""
        if frame in (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT):
            return "alt_msl_m", z
        if frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            return "alt_msl_m", v.home[2] + z
        if frame in (mav.MAV_FRAME_GLOBAL_TERRAIN_ALT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT):
            return "alt_agl_m", z
        return None

    def unsafe(self, v: MavVehicle, cmd: Command) -> str | None:
        """Why ``cmd`` would fly ``v`` into the ground or ask for a turn it
        cannot make (its class's rule, ``cosim.guidance.safety``: the rule of
        every command path), counted; None: it may fly it."""
        from cosim.vehicles import get_class

        problems = get_class(v.spec.vehicle_class).safety_problems(
            cmd, v.personality.limits(v), "the vehicle")
        if not problems:
            return None
        self.counts["commands_unsafe"] += 1
        return "; ".join(problems)

    def switch_to(self, v: MavVehicle, mode: int, d: dict[str, Any], out: Outcome, what: str,
                  refused: int = mav.MAV_RESULT_DENIED, cw: bool | None = None) -> int:
        """Turn vocabulary mapping ``d`` into a command for ``v`` in ``mode``; a
        mapping the vocabulary rejects is answered with a STATUSTEXT and
        ``refused``, a command that would crash (``unsafe``) with DENIED, both
        leaving the mode as it was. ``cw``: the loiter direction to fly."""
        cmd = vocab(d)
        if isinstance(cmd, str):
            out.replies.extend(text(f"{what}: {cmd}"))
            return refused
        problem = self.unsafe(v, cmd)
        if problem is not None:
            out.replies.extend(text(f"{what}: {problem}"))
            return mav.MAV_RESULT_DENIED
        if cw is not None:
            cmd = replace(cmd, loiter_cw=cw)
        v.mode = int(mode)
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED

    def fly_mission(self, v: MavVehicle, start: int, out: Outcome) -> int:
        """Switch ``v`` to its personality's mission mode (or stay in it) flying
        the mission from item ``start`` (0: from item 1), item by item
        (``cosim.mavlink.mission.MissionRunner``)."""
        from cosim.mavlink.mission import MissionRunner

        p = v.personality
        auto = p.auto_mode
        if auto is None or not p.autopilot:
            out.replies.extend(text("AUTO: this vehicle flies no missions"))
            return mav.MAV_RESULT_FAILED
        what = p.mode_name(auto)
        if not v.mission.items:
            out.replies.extend(text(f"{what}: no mission loaded"))
            return mav.MAV_RESULT_FAILED
        v.row_or_raise()
        why = MissionRunner(self).start(v, start, self.tick, out)
        if why is not None:
            out.replies.extend(text(f"{what}: {why}"))
            return mav.MAV_RESULT_FAILED
        v.mode = auto
        return mav.MAV_RESULT_ACCEPTED
