"""MAVLink parameters: a table of definitions (each class's personality
supplies its own, ``Personality.param_defs``), one vehicle's values, and the
parameters that follow a state column (``FollowedParams``).

Values travel as floats with the integer type in ``param_type``, cast the
way ArduPilot does (``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.mavlink import adapter as mav

if TYPE_CHECKING:
    from cosim.mavlink.vehicle import MavVehicle

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


#: every vehicle's system id (read-only here: ArduPilot needs a reboot too)
SYSID_THISMAV = ParamDef("SYSID_THISMAV", mav.MAV_PARAM_TYPE_INT16, 1, 1, 255, read_only=True)


class ParamTable:
    """One vehicle's parameter values (floats; integer types hold whole numbers)."""

    def __init__(self, defs: Sequence[ParamDef],
                 overrides: Mapping[str, float] | None = None) -> None:
        #: the definitions, in index order (PARAM_VALUE.param_index)
        self.defs = tuple(defs)
        #: name -> index
        self.index = {p.name: i for i, p in enumerate(self.defs)}
        self.values = [float(p.default) for p in self.defs]
        for name, value in (overrides or {}).items():
            if name not in self.index:
                raise ValueError(f"unknown MAVLink parameter {name!r}; known: "
                                 f"{', '.join(self.index)}")
            problem = self.check(name, value)
            if problem:
                raise ValueError(f"parameter {name}: {problem}")
            self.values[self.index[name]] = self._coerce(self.defs[self.index[name]], value)

    def __len__(self) -> int:
        return len(self.defs)

    def __contains__(self, name: object) -> bool:
        return name in self.index

    def __getitem__(self, name: str) -> float:
        return self.values[self.index[name]]

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.index, self.values))

    @staticmethod
    def _coerce(p: ParamDef, value: float) -> float:
        return float(round(value)) if p.is_int else float(value)

    def check(self, name: str, value: float) -> str | None:
        """Why ``value`` cannot be set (None: it can)."""
        p = self.defs[self.index[name]]
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
        p = self.defs[self.index[name]]
        if p.read_only:
            return "read-only"
        problem = self.check(name, value)
        if problem is None:
            self.values[self.index[name]] = self._coerce(p, value)
        return problem

    def force(self, name: str, value: float) -> None:
        """Set a value the vehicle itself owns (read-only ones included)."""
        self.values[self.index[name]] = self._coerce(self.defs[self.index[name]], value)


@dataclass
class _Followed:
    """A parameter following a state column on the vehicles in ``mask``, its
    values as last synced."""

    name: str
    column: int
    mask: np.ndarray
    lo: float
    hi: float
    last: np.ndarray


class FollowedParams:
    """The parameters that follow a state column on an endpoint's vehicles
    (``Personality.followed_params``), as ArduPilot's ROLL_LIMIT_DEG follows
    the bank limit in force, so that a change is announced (PARAM_VALUE)."""

    def __init__(self, vehicles: Sequence[MavVehicle]) -> None:
        self.vehicles = vehicles
        pairs = sorted({(n, c) for v in vehicles
                        for n, c in v.personality.followed_params.items()})
        self._followed = []
        for name, column in pairs:
            if column not in STATE_INDEX:
                raise ValueError(f"parameter {name} follows {column!r}, not a state column; "
                                 f"known: {', '.join(STATE_INDEX)}")
            mask = np.array([v.personality.followed_params.get(name) == column
                             for v in vehicles], dtype=bool)
            p = next(v.params.defs[v.params.index[name]] for v, m in zip(vehicles, mask) if m)
            self._followed.append(_Followed(name, STATE_INDEX[column], mask, p.lo, p.hi,
                                            np.full(len(vehicles), np.nan)))

    def sync(self, rows: np.ndarray) -> list[tuple[MavVehicle, str]]:
        """Set each followed parameter from ``rows`` (the vehicles' state rows)
        where its column changed to a value in the parameter's range; the
        (vehicle, parameter) whose value changed, in order."""
        out = []
        for f in self._followed:
            values = rows[:, f.column]
            changed = f.mask & (values != f.last) & (values >= f.lo) & (values <= f.hi)
            if changed.any():
                for j in np.flatnonzero(changed).tolist():
                    v = self.vehicles[j]
                    before = v.params[f.name]
                    v.params.force(f.name, float(values[j]))
                    if v.params[f.name] != before:
                        out.append((v, f.name))
                f.last = np.where(changed, values, f.last)
        return out
