"""The MAVLink services ask the vehicle's personality, never its class: a
personality written here (a rover with two modes, one parameter of its own
and one command) is what a ground station sees and what its commands do,
and what it does not support is refused the way MAVLink says."""

from __future__ import annotations

from mavtest import mavutil, of_type
from test_mav_commands import heartbeat, long, one_ack

from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import CommandRequest, Outcome, vocab
from cosim.mavlink.params import SYSID_THISMAV, ParamDef
from cosim.mavlink.personality import Personality
from cosim.mavlink.services.base import Context

ML = mavutil.mavlink
HOLD, CRUISE = 4, 7


class Rover(Personality):
    mav_type = mav.MAV_TYPE_GROUND_ROVER
    autopilot = True
    modes = {HOLD: "HOLD", CRUISE: "CRUISE"}
    param_defs = (ParamDef("CRUISE_SPEED", mav.MAV_PARAM_TYPE_REAL32, 12.0, 1.0, 40.0),
                  SYSID_THISMAV)

    def enter_mode(self, ctx: Context, v, mode: int, tick: int, out: Outcome) -> int:
        if mode == CRUISE:
            return ctx.switch_to(v, CRUISE, {"airspeed_mps": v.params["CRUISE_SPEED"]}, out,
                                 "CRUISE")
        return super().enter_mode(ctx, v, mode, tick, out)

    def command_handler(self, number: int):
        return self._change_speed if number == ML.MAV_CMD_DO_CHANGE_SPEED else None

    def supported_commands(self) -> frozenset[int]:
        return frozenset({ML.MAV_CMD_DO_CHANGE_SPEED})

    @staticmethod
    def _change_speed(ctx: Context, v, req: CommandRequest, tick: int, out: Outcome) -> int:
        cmd = vocab({"airspeed_mps": req.p[1]})
        if isinstance(cmd, str):
            return mav.MAV_RESULT_DENIED
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED


def test_heartbeat_modes_and_parameters_are_the_personalitys(rig) -> None:
    r = rig(1, personality=Rover())
    hb = heartbeat(r)
    assert (hb.type, hb.custom_mode) == (ML.MAV_TYPE_GROUND_ROVER, HOLD)
    _, replies = r.request(lambda: r.gcs.mav.param_request_list_send(1, 1))
    values = {p.param_id: p.param_value for p in of_type(replies, "PARAM_VALUE")}
    assert values == {"CRUISE_SPEED": 12.0, "SYSID_THISMAV": 1.0}
    cmds, replies = r.request(lambda: r.gcs.mav.set_mode_send(
        1, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, CRUISE))
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE) == ML.MAV_RESULT_ACCEPTED
    assert [c.command.airspeed_mps for c in cmds] == [12.0]
    assert heartbeat(r).custom_mode == CRUISE


def test_commands_are_the_personalitys_and_the_rest_unsupported(rig) -> None:
    r = rig(1, personality=Rover())
    cmds, replies = long(r, 1, ML.MAV_CMD_DO_CHANGE_SPEED, 0, 17.5)
    assert one_ack(replies, ML.MAV_CMD_DO_CHANGE_SPEED) == ML.MAV_RESULT_ACCEPTED
    assert [c.command.airspeed_mps for c in cmds] == [17.5]
    # ArduPlane's commands are not a rover's
    for number in (ML.MAV_CMD_COMPONENT_ARM_DISARM, ML.MAV_CMD_NAV_RETURN_TO_LAUNCH,
                   ML.MAV_CMD_DO_REPOSITION):
        cmds, replies = long(r, 1, number, 1)
        assert one_ack(replies, number) == ML.MAV_RESULT_UNSUPPORTED and cmds == []
    # the commands every vehicle answers still are
    _, replies = long(r, 1, ML.MAV_CMD_REQUEST_MESSAGE, ML.MAVLINK_MSG_ID_HOME_POSITION)
    assert one_ack(replies, ML.MAV_CMD_REQUEST_MESSAGE) == ML.MAV_RESULT_ACCEPTED
    assert len(of_type(replies, "HOME_POSITION")) == 1
    # a mode it does not have fails with a reason, the mode unchanged
    _, replies = long(r, 1, ML.MAV_CMD_DO_SET_MODE, ML.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 10)
    assert one_ack(replies, ML.MAV_CMD_DO_SET_MODE) == ML.MAV_RESULT_FAILED
    assert "not supported" in of_type(replies, "STATUSTEXT")[0].text
    assert heartbeat(r).custom_mode == HOLD


def test_no_missions_and_no_position_targets_without_support(rig) -> None:
    r = rig(1, personality=Rover())
    _, replies = r.request(lambda: r.gcs.mav.mission_count_send(1, 1, 2))
    ack, = of_type(replies, "MISSION_ACK")
    assert ack.type == ML.MAV_MISSION_UNSUPPORTED  # it flies no missions
    r.request(lambda: r.gcs.mav.set_position_target_global_int_send(
        0, 1, 1, ML.MAV_FRAME_GLOBAL_INT, 0b110111111000, 470100000, 80100000, 500,
        0, 0, 0, 0, 0, 0, 0, 0))
    assert r.ep.counters()["position_targets_ignored"] == 1
