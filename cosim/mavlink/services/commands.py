"""The command microservice: COMMAND_LONG, COMMAND_INT and SET_MODE, each
answered with exactly one COMMAND_ACK (SET_MODE as MAV_CMD_DO_SET_MODE, as
ArduPilot does). Results:

- ACCEPTED: done (the command, if any, is in ``Outcome.commands``)
- DENIED: the parameters are invalid (out of range, unknown frame or message)
- FAILED: valid, but not possible now (mode needs a mission, disarm in flight,
  pre-arm check, no autopilot); a STATUSTEXT says why
- UNSUPPORTED: a command the vehicle's class does not implement

Answered here alike for every vehicle: REQUEST_MESSAGE,
REQUEST_AUTOPILOT_CAPABILITIES, GET_HOME_POSITION, SET/GET_MESSAGE_INTERVAL,
DO_SET_MODE (the mode itself is the personality's), DO_SET_MISSION_CURRENT
and MISSION_START (the mission service's), DO_SET_ROI_LOCATION and
DO_SET_ROI_NONE (the gimbal cameras look at the point, or stop tracking and
hold their angles: the vocabulary's ``gimbal: {look_at: ...}``). Every other command is the
vehicle's personality's (``Personality.command_handler``).

Positions: COMMAND_LONG carries degrees in param5/6 and an altitude relative
to home in param7 (ArduPilot's convention); COMMAND_INT carries degE7 in
x/y and the altitude frame in ``frame`` (global = MSL, relative = above
home, terrain = above ground). A position of (0, 0) or INT32_MAX means
"where the vehicle is" (``CommandRequest.location``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from cosim.mavlink import adapter as mav
from cosim.mavlink.outcome import (
    CommandRequest,
    Outcome,
    as_int,
    command_ack,
    roi_vocab,
    text,
    vocab,
)
from cosim.mavlink.services.base import Context
from cosim.mavlink.vehicle import DEFAULT_RATES_HZ, STREAMABLE, MavVehicle, period_ticks

if TYPE_CHECKING:
    from cosim.mavlink.personality import Personality
    from cosim.mavlink.services.missions import MissionService

#: the longest stream interval SET_MESSAGE_INTERVAL may ask for (us): an hour
MAX_INTERVAL_US = 3_600_000_000


class CommandService:
    """COMMAND_LONG / COMMAND_INT / SET_MODE for the vehicles of one endpoint."""

    def __init__(self, ctx: Context, missions: MissionService) -> None:
        self.ctx = ctx
        self.missions = missions
        self.messages = {"COMMAND_LONG": self.command, "COMMAND_INT": self.command,
                         "SET_MODE": self.set_mode_msg}
        self._common: dict[int, Callable[[MavVehicle, CommandRequest, int, Outcome], int]] = {
            mav.MAV_CMD_DO_SET_MODE: self._do_set_mode,
            mav.MAV_CMD_REQUEST_MESSAGE: self._request_message,
            mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._request_capabilities,
            mav.MAV_CMD_GET_HOME_POSITION: self._get_home,
            mav.MAV_CMD_SET_MESSAGE_INTERVAL: self._set_interval,
            mav.MAV_CMD_GET_MESSAGE_INTERVAL: self._get_interval,
            mav.MAV_CMD_DO_SET_MISSION_CURRENT: self._do_set_mission_current,
            mav.MAV_CMD_MISSION_START: self._mission_start,
            mav.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION: self._video_info,
            mav.MAV_CMD_DO_SET_ROI_LOCATION: self._roi,
            mav.MAV_CMD_DO_SET_ROI_NONE: self._roi,
        }

    def supported(self, personality: Personality) -> frozenset[int]:
        """The MAV_CMD numbers a vehicle with ``personality`` answers (others:
        UNSUPPORTED)."""
        return frozenset(self._common) | personality.supported_commands()

    def command(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        req = CommandRequest.of(m)
        common = self._common.get(req.command)
        if common is not None:
            res = common(v, req, tick, out)
        else:
            fn = v.personality.command_handler(req.command)
            if fn is None:
                self.ctx.counts["unsupported_commands"] += 1
                res = mav.MAV_RESULT_UNSUPPORTED
            else:
                res = fn(self.ctx, v, req, tick, out)
        if res != mav.MAV_RESULT_ACCEPTED:
            self.ctx.counts["commands_refused"] += 1
        # the ACK goes after any STATUSTEXT but before requested messages
        at = sum(1 for name, _ in out.replies if name == "STATUSTEXT")
        out.replies.insert(at, command_ack(m, req.command, res))
        return out

    # -- modes ---------------------------------------------------------------------
    def set_mode_msg(self, v: MavVehicle, m: mav.Message, tick: int) -> Outcome:
        out = Outcome()
        res = self._set_mode(v, int(m.fields["base_mode"]), float(m.fields["custom_mode"]),
                             tick, out)
        out.replies.append(command_ack(m, mav.MAV_CMD_DO_SET_MODE, res))
        return out

    def _set_mode(self, v: MavVehicle, base_mode: int | None, custom: float, tick: int,
                  out: Outcome) -> int:
        mode = as_int(custom)
        if base_mode is None or not base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED \
                or mode is None:
            out.replies.extend(text("set mode: use the vehicle's custom modes"))
            return mav.MAV_RESULT_DENIED
        return v.personality.enter_mode(self.ctx, v, mode, tick, out)

    def _do_set_mode(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        return self._set_mode(v, as_int(req.p[0]), req.p[1], tick, out)

    def _roi(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        """DO_SET_ROI_LOCATION: the gimbal cameras look at x/y (z: its altitude
        in the command's frame); no location, or DO_SET_ROI_NONE: they stop
        tracking and hold their angles."""
        where = None if req.command == mav.MAV_CMD_DO_SET_ROI_NONE else req.location()
        alt = self.ctx.alt(v, req.frame, req.z) if where is not None and math.isfinite(req.z) \
            else None
        cmd = vocab(roi_vocab(where, alt))
        if isinstance(cmd, str):
            out.replies.extend(text(f"ROI: {cmd}"))
            return mav.MAV_RESULT_DENIED
        out.commands.append(cmd)
        return mav.MAV_RESULT_ACCEPTED

    # -- messages and streams --------------------------------------------------------
    def _send_message(self, v: MavVehicle, name: str | None, tick: int, out: Outcome) -> int:
        if name not in STREAMABLE:
            return mav.MAV_RESULT_DENIED
        out.replies.append((name, v.fields(name, tick)))
        return mav.MAV_RESULT_ACCEPTED

    def _video_info(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome,
                    stream: float | None = None) -> int:
        """VIDEO_STREAM_INFORMATION of stream param1 (0: every one) of a
        vehicle whose camera is streamed (``cosim run --video``)."""
        sid = as_int(req.p[0] if stream is None else stream)
        infos = [i for i in v.video if sid in (0, None) or i["stream_id"] == sid]
        if not infos:
            out.replies.extend(text("no video stream" if not v.video else
                                    f"no video stream {sid}"))
            return mav.MAV_RESULT_FAILED if not v.video else mav.MAV_RESULT_DENIED
        out.replies.extend(("VIDEO_STREAM_INFORMATION", {**i, "camera_device_id": 0})
                           for i in infos)
        return mav.MAV_RESULT_ACCEPTED

    def _request_message(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome
                         ) -> int:
        mid = as_int(req.p[0])
        if mid == mav.msg_id("VIDEO_STREAM_INFORMATION"):  # param2: the stream (0: all)
            return self._video_info(v, req, tick, out, req.p[1])
        return self._send_message(v, None if mid is None else mav.msg_name(mid), tick, out)

    def _request_capabilities(self, v: MavVehicle, req: CommandRequest, tick: int,
                              out: Outcome) -> int:
        if as_int(req.p[0]) != 1:
            return mav.MAV_RESULT_ACCEPTED  # nothing requested
        return self._send_message(v, "AUTOPILOT_VERSION", tick, out)

    def _get_home(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        return self._send_message(v, "HOME_POSITION", tick, out)

    def _set_interval(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        mid, interval = as_int(req.p[0]), req.p[1]
        name = None if mid is None else mav.msg_name(mid)
        if name not in STREAMABLE or not math.isfinite(interval) \
                or not -1 <= interval <= MAX_INTERVAL_US:
            return mav.MAV_RESULT_DENIED
        hz = self.ctx.physics_hz
        if interval == -1:
            period = None
        elif interval == 0:
            period = period_ticks(DEFAULT_RATES_HZ.get(name, 0.0), hz)
        else:
            period = max(1, round(interval * 1e-6 * hz))
        v.set_period(name, period, tick)
        return mav.MAV_RESULT_ACCEPTED

    def _get_interval(self, v: MavVehicle, req: CommandRequest, tick: int, out: Outcome) -> int:
        mid = as_int(req.p[0])
        name = None if mid is None else mav.msg_name(mid)
        if mid is None or not 0 <= mid <= 0xFFFF:  # MESSAGE_INTERVAL.message_id: uint16
            return mav.MAV_RESULT_DENIED
        if name not in STREAMABLE:
            us = 0  # not available
        else:
            p = v.period[name]
            us = -1 if p is None else round(p * 1e6 / self.ctx.physics_hz)
        out.replies.append(("MESSAGE_INTERVAL", {"message_id": mid, "interval_us": us}))
        return mav.MAV_RESULT_ACCEPTED

    def _mission_start(self, v: MavVehicle, req: CommandRequest, tick: int,
                       out: Outcome) -> int:
        """MISSION_START: param1 the first item (0: the current one)."""
        first = as_int(req.p[0])
        if first is None or first < 0:
            return mav.MAV_RESULT_DENIED
        return self.missions.start(v, first, out)

    def _do_set_mission_current(self, v: MavVehicle, req: CommandRequest, tick: int,
                                out: Outcome) -> int:
        seq = as_int(req.p[0])
        if seq is None or seq == -1:  # -1: leave the current item as it is
            return mav.MAV_RESULT_ACCEPTED
        return self.missions.set_current(v, seq, out)
