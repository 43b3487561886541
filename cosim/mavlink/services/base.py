"""The ``Context`` the MAVLink services and the personalities work in:
the endpoint's counters, the physics rate, the tick being handled, altitude
frames, the class's safety rule, and a mode switch with its command."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.mission_runner import MissionRunner
from cosim.mavlink.outcome import Outcome, text, vocab

if TYPE_CHECKING:
    from cosim.mavlink.vehicle import MavVehicle


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
        cannot make (the rule its class handed down, ``MavVehicleSpec.safety``;
        ``cosim.guidance.safety``: the rule of every command path), counted;
        None: it may fly it."""
        rule = v.spec.safety
        problems = [] if rule is None else rule(cmd, v.personality.limits(v), "the vehicle")
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
        (``cosim.mavlink.mission_runner.MissionRunner``)."""
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
