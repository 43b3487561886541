"""The one rule every command path applies before a command reaches guidance:
nothing that flies a vehicle into the ground or asks for a turn it cannot make.

- Heights: every altitude a command asks for (its own ``alt_*``, each
  point's) must be at least the class minimum above the ground under the
  vehicle (the scenario's ground is flat at ``terrain_alt_m``). Fixed-wing
  aircraft: ``DEFAULT_MIN_ALT_AGL_M`` (20 m), or ``min_alt_agl_m`` in the
  aircraft's profile; the study's lowest passes were 30 m above the ground.
- Radii: a loiter radius (of a goto, waypoints or loiter) at least the
  minimum turn radius ``v^2 / (g tan(phi))`` at the airspeed the command
  leaves in force and the bank limit.

Used by the scenario schedule (line-numbered errors), by the MAVLink
handlers (MAV_RESULT_DENIED, or the mission protocol's refusal of that item,
with a STATUSTEXT saying why) and so by the swarm controller and outside
controllers, which command through MAVLink: one rule on every path.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from cosim.geo import KT_TO_MPS
from cosim.guidance.commands import Command, min_turn_radius_m

#: how low a fixed-wing may be commanded, above the ground (m)
DEFAULT_MIN_ALT_AGL_M = 20.0


def min_alt_agl_m(profile: Mapping[str, Any]) -> float:
    """The class minimum height above the ground for a model's profile."""
    v = profile.get("min_alt_agl_m", DEFAULT_MIN_ALT_AGL_M)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) \
        else DEFAULT_MIN_ALT_AGL_M


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


def command_problems(cmd: Command, lim: Limits, who: str = "the vehicle") -> list[str]:
    """Why ``cmd`` would fly ``who`` into the ground or ask for a turn it
    cannot make (empty: it may fly it)."""
    problems = []
    floor = lim.terrain_alt_m + lim.min_agl_m
    for alt, agl in [(cmd.alt_m, cmd.alt_agl)] + [(p.alt_m, p.alt_agl) for p in cmd.points]:
        if alt is None:
            continue
        msl = lim.terrain_alt_m + alt if agl else alt
        if msl < floor - 1e-6:
            problems.append(f"altitude {msl:.0f} m MSL is {msl - lim.terrain_alt_m:.0f} m above "
                            f"the ground (at {lim.terrain_alt_m:.0f} m); {who} must stay at "
                            f"least {lim.min_agl_m:g} m above it")
            break
    if cmd.loiter_radius_m is not None:
        speed = speed_after(cmd, lim.airspeed_mps)
        bank = cmd.bank_limit_deg if cmd.bank_limit_deg is not None else lim.bank_limit_deg
        r_min = min_turn_radius_m(speed, bank)
        if cmd.loiter_radius_m < r_min - 1e-6:
            problems.append(f"loiter radius {cmd.loiter_radius_m:g} m is below the minimum "
                            f"turn radius of {who} ({r_min:.0f} m at {speed / KT_TO_MPS:.0f} kt "
                            f"and a {bank:g} deg bank limit)")
    return problems
