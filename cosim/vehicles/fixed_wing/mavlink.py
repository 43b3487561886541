"""The fixed-wing class on MAVLink: an ArduPlane (MAV_TYPE_FIXED_WING,
ArduPilot's autopilot type, ArduPlane's custom modes)."""

from __future__ import annotations

from enum import IntEnum

from cosim.mavlink import adapter as mav
from cosim.mavlink.personality import Personality


class PlaneMode(IntEnum):
    """ArduPlane custom mode numbers (HEARTBEAT.custom_mode)."""

    MANUAL = 0
    CIRCLE = 1
    STABILIZE = 2
    TRAINING = 3
    ACRO = 4
    FBWA = 5
    FBWB = 6
    CRUISE = 7
    AUTOTUNE = 8
    AUTO = 10
    RTL = 11
    LOITER = 12
    TAKEOFF = 13
    AVOID_ADSB = 14
    GUIDED = 15
    THERMAL = 24


#: modes in which ArduPlane reports MAV_MODE_FLAG_MANUAL_INPUT_ENABLED only
_MANUAL_MODES = {PlaneMode.MANUAL, PlaneMode.TRAINING, PlaneMode.ACRO}
#: modes ArduPlane reports as GUIDED_ENABLED | STABILIZE_ENABLED
_GUIDED_MODES = {PlaneMode.AUTO, PlaneMode.RTL, PlaneMode.LOITER, PlaneMode.AVOID_ADSB,
                 PlaneMode.GUIDED, PlaneMode.CIRCLE, PlaneMode.TAKEOFF, PlaneMode.THERMAL}


class ArduPlane(Personality):
    """ArduPlane, flown by cosim's autopilot (``autopilot``) or, for a JSBSim
    model without one, a plane in MANUAL that takes no commands."""

    mav_type = mav.MAV_TYPE_FIXED_WING
    autopilot_type = mav.MAV_AUTOPILOT_ARDUPILOTMEGA
    modes = {int(m): m.name for m in PlaneMode}
    auto_mode = int(PlaneMode.AUTO)

    def __init__(self, autopilot: bool = True) -> None:
        self.autopilot = autopilot

    def default_mode(self) -> int:
        return int(PlaneMode.GUIDED if self.autopilot else PlaneMode.MANUAL)

    def manual(self, mode: int) -> bool:
        return mode in _MANUAL_MODES

    def base_mode(self, mode: int, armed: bool) -> int:
        """As ArduPlane computes it (stick mixing off: no RC)."""
        if mode in _MANUAL_MODES:
            bm = mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        elif mode in _GUIDED_MODES:
            bm = mav.MAV_MODE_FLAG_GUIDED_ENABLED | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        else:
            bm = mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        if armed:
            bm |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        return bm | mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


#: the fixed-wing class's personality, and a plain JSBSim model's
ARDUPLANE = ArduPlane(autopilot=True)
ARDUPLANE_NO_AUTOPILOT = ArduPlane(autopilot=False)
