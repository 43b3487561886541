"""guidance: the fixed-wing command vocabulary and path following.

Turns commands (from the schedule now; MAVLink and the swarm controller
later) into setpoints for the cosim autopilot that runs inside JSBSim. It
reads vehicles only through the state array and writes only setpoints.
"""

from cosim.guidance.commands import (
    COMMAND_KEYS,
    DEFAULT_BANK_LIMIT_DEG,
    Command,
    Point,
    min_turn_radius_m,
    parse_command,
)
from cosim.guidance.fixed_wing import AP_CHANNELS, FixedWingGuidance, GuidanceEvent

__all__ = ["AP_CHANNELS", "COMMAND_KEYS", "DEFAULT_BANK_LIMIT_DEG", "Command",
           "FixedWingGuidance", "GuidanceEvent", "Point", "min_turn_radius_m", "parse_command"]
