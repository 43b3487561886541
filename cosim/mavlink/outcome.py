"""What handling a MAVLink message produces, and the replies every part
sends: the shape of an answer (``Outcome``: replies, commands for guidance,
run events), COMMAND_LONG and COMMAND_INT in one shape (``CommandRequest``),
COMMAND_ACK, MISSION_ACK, chunked STATUSTEXT, and the one command
vocabulary (``vocab``). The services, the personalities and the mission
runner all answer in these; this module needs nothing of them."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

from cosim.guidance.commands import Command, parse_command
from cosim.mavlink import adapter as mav

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


def roi_vocab(location: tuple[float, float] | None, alt: tuple[str, float] | None
              ) -> dict[str, Any]:
    """DO_SET_ROI_LOCATION (and a mission's DO_SET_ROI) as the vocabulary's
    gimbal command: look at (lat_deg, lon_deg) at ``alt`` ((vocabulary key,
    metres) as ``Context.alt`` gives it; None: the ground); no location (x =
    y = 0, as ArduPilot reads it) or DO_SET_ROI_NONE: stop tracking, the
    gimbal holding its angles."""
    if location is None:
        return {"gimbal": {"look_at": None}}
    point: dict[str, Any] = {"lat_deg": location[0], "lon_deg": location[1]}
    if alt is not None:
        point[alt[0]] = alt[1]
    return {"gimbal": {"look_at": point}}


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
