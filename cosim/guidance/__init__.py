"""guidance: the command vocabulary every command path shares, and the
safety rules classes build theirs from.

``Command`` is the one command object: the schedule's ``command:``,
MAVLink clients (through the handlers), the swarm controller and outside
controllers (through MAVLink) all produce it; the runner routes it to the
vehicle's class, whose guidance (``cosim.vehicles``) turns it into
setpoints. This package never reads vehicles or writes setpoints.
"""

from cosim.guidance.commands import (
    COMMAND_KEYS,
    DEFAULT_BANK_LIMIT_DEG,
    Command,
    Point,
    min_turn_radius_m,
    parse_command,
)

__all__ = ["COMMAND_KEYS", "DEFAULT_BANK_LIMIT_DEG", "Command", "Point", "min_turn_radius_m",
           "parse_command"]
