"""The parameter set each MAVLink vehicle exposes (ArduPlane names).

A small, real set: every parameter here changes what the vehicle does.

=================  =======  ========  ==================================================
name               type     default   effect
=================  =======  ========  ==================================================
ARMING_CHECK       INT32    1         0: arm without pre-arm checks; otherwise arming a
                                      crashed or diverged vehicle fails
ALT_HOLD_RTL       INT32    10000     RTL altitude above home (cm); -1: keep altitude
RTL_RADIUS         INT16    0         RTL loiter radius (m, <0 ccw); 0: WP_LOITER_RAD
WP_LOITER_RAD      INT16    0         loiter radius (m, <0 ccw) for LOITER, GUIDED and
                                      repositions without their own radius; 0 (cosim):
                                      guidance's bank-limited default
TKOFF_ALT          INT16    50        TAKEOFF climb target above home (m)
AIRSPEED_CRUISE    REAL32   (model)   airspeed restored on arming and flown in RTL (m/s)
AIRSPEED_MIN       INT16    (model)   lowest speed DO_CHANGE_SPEED/DO_REPOSITION accept
AIRSPEED_MAX       INT16    (model)   highest speed they accept (m/s)
ROLL_LIMIT_DEG     REAL32   45        guidance bank limit (sent as a command on change)
STALL_PREVENTION   INT8     1         the autopilot's stall protection (sent on change)
SYSID_THISMAV      INT16    (sysid)   read-only here (ArduPilot needs a reboot too)
=================  =======  ========  ==================================================

Values travel as floats with the integer type in ``param_type``, cast the
way ArduPilot does (``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from cosim.guidance.commands import DEFAULT_BANK_LIMIT_DEG
from cosim.mavlink import adapter as mav

_INT_RANGE = {mav.MAV_PARAM_TYPE_INT8: (-128, 127), mav.MAV_PARAM_TYPE_INT16: (-32768, 32767),
              mav.MAV_PARAM_TYPE_INT32: (-2 ** 31, 2 ** 31 - 1)}


@dataclass(frozen=True)
class ParamDef:
    name: str
    mav_type: int
    default: float
    lo: float
    hi: float
    read_only: bool = False

    @property
    def is_int(self) -> bool:
        return self.mav_type != mav.MAV_PARAM_TYPE_REAL32


#: the table, in index order (PARAM_VALUE.param_index)
PARAM_DEFS: tuple[ParamDef, ...] = (
    ParamDef("AIRSPEED_CRUISE", mav.MAV_PARAM_TYPE_REAL32, 25.0, 1.0, 300.0),
    ParamDef("AIRSPEED_MAX", mav.MAV_PARAM_TYPE_INT16, 100, 1, 300),
    ParamDef("AIRSPEED_MIN", mav.MAV_PARAM_TYPE_INT16, 10, 1, 300),
    ParamDef("ALT_HOLD_RTL", mav.MAV_PARAM_TYPE_INT32, 10000, -1, 3_000_000),
    ParamDef("ARMING_CHECK", mav.MAV_PARAM_TYPE_INT32, 1, 0, 2 ** 31 - 1),
    ParamDef("ROLL_LIMIT_DEG", mav.MAV_PARAM_TYPE_REAL32, DEFAULT_BANK_LIMIT_DEG, 5.0, 75.0),
    ParamDef("RTL_RADIUS", mav.MAV_PARAM_TYPE_INT16, 0, -32767, 32767),
    ParamDef("STALL_PREVENTION", mav.MAV_PARAM_TYPE_INT8, 1, 0, 1),
    ParamDef("SYSID_THISMAV", mav.MAV_PARAM_TYPE_INT16, 1, 1, 255, read_only=True),
    ParamDef("TKOFF_ALT", mav.MAV_PARAM_TYPE_INT16, 50, 0, 30000),
    ParamDef("WP_LOITER_RAD", mav.MAV_PARAM_TYPE_INT16, 0, -32767, 32767),
)
PARAM_INDEX: dict[str, int] = {p.name: i for i, p in enumerate(PARAM_DEFS)}


class ParamTable:
    """One vehicle's parameter values (floats; integer types hold whole numbers)."""

    def __init__(self, overrides: Mapping[str, float] | None = None) -> None:
        self.values = [float(p.default) for p in PARAM_DEFS]
        for name, value in (overrides or {}).items():
            if name not in PARAM_INDEX:
                raise ValueError(f"unknown MAVLink parameter {name!r}; known: "
                                 f"{', '.join(PARAM_INDEX)}")
            problem = self.check(name, value)
            if problem:
                raise ValueError(f"parameter {name}: {problem}")
            self.values[PARAM_INDEX[name]] = self._coerce(PARAM_DEFS[PARAM_INDEX[name]], value)

    def __len__(self) -> int:
        return len(PARAM_DEFS)

    def __getitem__(self, name: str) -> float:
        return self.values[PARAM_INDEX[name]]

    @staticmethod
    def _coerce(p: ParamDef, value: float) -> float:
        return float(round(value)) if p.is_int else float(value)

    def check(self, name: str, value: float) -> str | None:
        """Why ``value`` cannot be set (None: it can)."""
        p = PARAM_DEFS[PARAM_INDEX[name]]
        if not math.isfinite(value):
            return f"not a finite number: {value!r}"
        v = self._coerce(p, value)
        if p.is_int:
            lo, hi = _INT_RANGE[p.mav_type]
            if not lo <= v <= hi:
                return f"{v:g} does not fit the parameter's type"
        if not p.lo <= v <= p.hi:
            return f"{v:g} is outside {p.lo:g}..{p.hi:g}"
        return None

    def set(self, name: str, value: float) -> str | None:
        """Set a parameter; returns why not (None: set)."""
        p = PARAM_DEFS[PARAM_INDEX[name]]
        if p.read_only:
            return "read-only"
        problem = self.check(name, value)
        if problem is None:
            self.values[PARAM_INDEX[name]] = self._coerce(p, value)
        return problem

    def force(self, name: str, value: float) -> None:
        """Set a value the vehicle itself owns (read-only ones included)."""
        self.values[PARAM_INDEX[name]] = self._coerce(PARAM_DEFS[PARAM_INDEX[name]], value)
