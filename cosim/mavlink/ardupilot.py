"""What ArduPilot's vehicle firmwares share on MAVLink, for the personalities
that copy one (ArduCopter, ArduRover): modes by a table, arming
(COMPONENT_ARM_DISARM; disarming in the air needs param2 = 21196, as in
ArduPilot), DO_REPOSITION and DO_CHANGE_SPEED. Each mode of the table is a
vocabulary mapping (a function of the vehicle: home, ...); a mode in
``refused`` is refused with its reason; the mission mode flies the mission."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from cosim.mavlink import adapter as mav
from cosim.mavlink.personality import CommandFn, Personality
from cosim.mavlink.services.base import CommandRequest, Context, Outcome, as_int, text

if TYPE_CHECKING:
    from cosim.mavlink.vehicle import MavVehicle

ModeVocab = Callable[["MavVehicle"], dict[str, Any]]
#: COMPONENT_ARM_DISARM param2 that forces a disarm in the air (ArduPilot's)
FORCE_MAGIC = 21196


class ArduPilotLike(Personality):
    """See the module docstring."""

    autopilot_type = mav.MAV_AUTOPILOT_ARDUPILOTMEGA
    autopilot = True
    #: mode -> the vocabulary mapping it flies (modes not here: not supported)
    mode_vocab: Mapping[int, ModeVocab] = {}
    #: mode -> why cosim refuses it (e.g. a pilot's mode)
    refused: Mapping[int, str] = {}
    #: the mode DO_REPOSITION switches to
    guided_mode: int = 0
    #: whether DO_REPOSITION keeps its altitude (aircraft) or drops it (ground)
    reposition_alt: bool = True

    def default_mode(self) -> int:
        return self.hold_mode if self.hold_mode is not None else super().default_mode()

    def manual(self, mode: int) -> bool:
        return mode in self.refused

    def enter_mode(self, ctx: Context, v: MavVehicle, mode: int, tick: int,
                   out: Outcome) -> int:
        if mode == v.mode:
            return mav.MAV_RESULT_ACCEPTED
        name = self.mode_name(mode)
        if mode == self.auto_mode:
            return ctx.fly_mission(v, v.mission.current, out)
        if mode in self.refused:
            out.replies.extend(text(f"{name}: {self.refused[mode]}"))
            return mav.MAV_RESULT_FAILED
        vocab_of = self.mode_vocab.get(mode)
        if vocab_of is None:
            out.replies.extend(text(f"{name} is not supported by cosim"))
            return mav.MAV_RESULT_FAILED
        return ctx.switch_to(v, mode, vocab_of(v), out, name, mav.MAV_RESULT_FAILED)

    def command_handler(self, number: int) -> CommandFn | None:
        return {mav.MAV_CMD_DO_REPOSITION: self._reposition,
                mav.MAV_CMD_DO_CHANGE_SPEED: self._change_speed,
                mav.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm}.get(number)

    def supported_commands(self) -> frozenset[int]:
        return frozenset({mav.MAV_CMD_DO_REPOSITION, mav.MAV_CMD_DO_CHANGE_SPEED,
                          mav.MAV_CMD_COMPONENT_ARM_DISARM})

    @staticmethod
    def _arm_disarm(ctx: Context, v: Any, req: CommandRequest, tick: int, out: Outcome) -> int:
        want, force = as_int(req.p[0]), as_int(req.p[1]) == FORCE_MAGIC
        if want == 1:
            if not v.armed and not force and not v.prearm_ok():
                out.replies.extend(text("PreArm: vehicle crashed or diverged"))
                return mav.MAV_RESULT_FAILED
            v.armed = True
            return mav.MAV_RESULT_ACCEPTED
        if want == 0:
            if v.armed and v.in_air() and not force:
                out.replies.extend(text(f"Disarm refused in flight (param2={FORCE_MAGIC} "
                                        f"forces)"))
                return mav.MAV_RESULT_FAILED
            v.armed = False
            return mav.MAV_RESULT_ACCEPTED
        return mav.MAV_RESULT_DENIED

    @staticmethod
    def _change_speed(ctx: Context, v: Any, req: CommandRequest, tick: int,
                      out: Outcome) -> int:
        """DO_CHANGE_SPEED: param2 m/s, checked by the class's rule."""
        return ctx.switch_to(v, v.mode, {"airspeed_mps": req.p[1]}, out, "change speed")

    def _reposition(self, ctx: Context, v: Any, req: CommandRequest, tick: int,
                    out: Outcome) -> int:
        """DO_REPOSITION: go to the point (speed param1 when > 0) and stop there,
        in the guided mode."""
        if not req.is_int:
            out.replies.extend(text("reposition: send it as COMMAND_INT"))
            return mav.MAV_RESULT_DENIED
        goto: dict[str, Any] = {"lat_deg": req.x * 1e-7, "lon_deg": req.y * 1e-7}
        alt = ctx.alt(v, req.frame, req.z) if self.reposition_alt else None
        if alt is not None:
            goto[alt[0]] = alt[1]
        if req.p[0] > 0:
            goto["airspeed_mps"] = req.p[0]
        return ctx.switch_to(v, self.guided_mode, {"goto": goto}, out, "reposition")


def home_goto(v: MavVehicle) -> dict[str, Any]:
    """A vocabulary point at the vehicle's home."""
    return {"lat_deg": v.home[0], "lon_deg": v.home[1]}
