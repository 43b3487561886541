"""The rule every command path applies before a command reaches guidance:
nothing that flies a vehicle into the ground or asks for a turn it cannot
make. Classes build theirs from these checks (``VehicleClass.safety_problems``):

- ``floor_problems``: every altitude a command asks for (its own ``alt_*``,
  each point's) at least the class minimum above the ground under the
  vehicle (the scenario's ground is flat at ``terrain_alt_m``);
- ``radius_problems``: a loiter radius (of a goto, waypoints or loiter) at
  least the minimum turn radius ``v^2 / (g tan(phi))`` at the airspeed the
  command leaves in force and the bank limit.

Used by the scenario schedule (line-numbered errors), by the MAVLink
handlers (MAV_RESULT_DENIED, or the mission protocol's refusal of that item,
with a STATUSTEXT saying why) and so by the swarm controller and outside
controllers, which command through MAVLink: one rule on every path.
"""

from __future__ import annotations

from dataclasses import dataclass

from cosim.core.units import KT_TO_MPS
from cosim.guidance.commands import Command, min_turn_radius_m


@dataclass(frozen=True)
class Limits:
    """What one vehicle can fly when the command arrives."""

    terrain_alt_m: float  # the ground under it (MSL)
    min_agl_m: float  # the class minimum above the ground
    airspeed_mps: float  # the airspeed in force (a command without one keeps it)
    bank_limit_deg: float  # the bank limit in force


def speed_after(cmd: Command, airspeed_mps: float) -> float:
    """The airspeed in force once ``cmd`` is flown (its last point's, its own,
    else the one before)."""
    for spd in reversed([cmd.airspeed_mps] + [p.airspeed_mps for p in cmd.points]):
        if spd is not None:
            return spd
    return airspeed_mps


def floor_problems(cmd: Command, lim: Limits, who: str = "the vehicle") -> list[str]:
    """An altitude of ``cmd`` below the class minimum above the ground."""
    floor = lim.terrain_alt_m + lim.min_agl_m
    for alt, agl in [(cmd.alt_m, cmd.alt_agl)] + [(p.alt_m, p.alt_agl) for p in cmd.points]:
        if alt is None:
            continue
        msl = lim.terrain_alt_m + alt if agl else alt
        if msl < floor - 1e-6:
            return [f"altitude {msl:.0f} m MSL is {msl - lim.terrain_alt_m:.0f} m above the "
                    f"ground (at {lim.terrain_alt_m:.0f} m); {who} must stay at least "
                    f"{lim.min_agl_m:g} m above it"]
    return []


def radius_problems(cmd: Command, lim: Limits, who: str = "the vehicle") -> list[str]:
    """A loiter radius of ``cmd`` below the minimum turn radius."""
    if cmd.loiter_radius_m is None:
        return []
    speed = speed_after(cmd, lim.airspeed_mps)
    bank = cmd.bank_limit_deg if cmd.bank_limit_deg is not None else lim.bank_limit_deg
    r_min = min_turn_radius_m(speed, bank)
    if cmd.loiter_radius_m < r_min - 1e-6:
        return [f"loiter radius {cmd.loiter_radius_m:g} m is below the minimum turn radius "
                f"of {who} ({r_min:.0f} m at {speed / KT_TO_MPS:.0f} kt and a {bank:g} deg "
                f"bank limit)"]
    return []
