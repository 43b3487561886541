"""A vehicle class's MAVLink personality: what a ground station sees of it
and how its modes behave. Each class supplies one (``VehicleClass.mavlink``);
the endpoint and its services ask the vehicle's personality and never which
class it is.

The base describes a vehicle with no modes of its own; a class's personality
(e.g. ArduPlane's, ``cosim.vehicles.fixed_wing.mavlink``) overrides it.
"""

from __future__ import annotations

from collections.abc import Mapping

from cosim.mavlink import adapter as mav


class Personality:
    """How one class of vehicle appears on MAVLink (see the module docstring)."""

    #: HEARTBEAT.type
    mav_type: int = mav.MAV_TYPE_FIXED_WING
    #: HEARTBEAT.autopilot
    autopilot_type: int = mav.MAV_AUTOPILOT_ARDUPILOTMEGA
    #: whether the vehicle takes commands (modes, navigation) at all
    autopilot: bool = False
    #: custom mode number -> name
    modes: Mapping[int, str] = {0: "MANUAL"}
    #: the mode a mission is flown in (None: no missions)
    auto_mode: int | None = None

    def default_mode(self) -> int:
        """The mode a vehicle starts in."""
        return next(iter(self.modes))

    def mode_name(self, number: int) -> str:
        return self.modes.get(number, f"mode {number}")

    def manual(self, mode: int) -> bool:
        """Whether ``mode`` is flown by a pilot (no autopilot loops enabled)."""
        return True

    def base_mode(self, mode: int, armed: bool) -> int:
        """HEARTBEAT.base_mode in ``mode``."""
        bm = mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED if self.manual(mode) \
            else mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        if armed:
            bm |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        return bm | mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
