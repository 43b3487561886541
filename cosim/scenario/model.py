"""The scenario as the rest of cosim sees it: a validated, frozen
``Scenario`` (its origin, rates, duration, seed, vehicles, schedule, the
sections' parsed objects and the world they make) and its parts' types."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

from cosim.core import limits as lim
from cosim.core.geo import LocalFrame
from cosim.core.state import VehicleSpec
from cosim.guidance import Command
from cosim.vehicles import get_class
from cosim.world.model import World

SCHEMA_VERSION = 1


@dataclass(frozen=True)
class Origin:
    lat_deg: float
    lon_deg: float
    ground_alt_m: float = 0.0

    @property
    def frame(self) -> LocalFrame:
        return LocalFrame(self.lat_deg, self.lon_deg, self.ground_alt_m)


@dataclass(frozen=True)
class Rates:
    physics_hz: float = 120.0
    control_hz: float = 30.0
    log_hz: float = 10.0

    @property
    def dt_s(self) -> float:
        return 1.0 / self.physics_hz

    @property
    def control_every(self) -> int:
        """Physics ticks per control exchange."""
        return round(self.physics_hz / self.control_hz)

    @property
    def log_every(self) -> int:
        """Physics ticks per logged row."""
        return round(self.physics_hz / self.log_hz)


@dataclass(frozen=True)
class ScheduleItem:
    at_s: float
    tick: int  # the control tick at which it applies (first at or after at_s)
    vehicles: tuple[int, ...]  # indices into Scenario.vehicles
    sets: tuple[tuple[str, float], ...]
    index: int = 0  # position in the file's schedule list
    command: Command | None = None  # the fixed-wing command vocabulary


@dataclass(frozen=True)
class Scenario:
    name: str
    path: str
    origin: Origin
    rates: Rates
    duration_s: float
    seed: int
    vehicles: tuple[VehicleSpec, ...]
    schedule: tuple[ScheduleItem, ...] = ()
    description: str = ""
    aircraft_path: tuple[str, ...] = ()
    plot: bool = False  # write track.png (ground track and altitude) after the run
    #: MAVLink link of the run: {"url": ..., "rates_hz": {...}}; None: no MAVLink
    mavlink: dict[str, Any] | None = None
    #: parsed top-level sections (``cosim.scenario.sections``): key -> object
    sections: dict[str, Any] = field(default_factory=dict, compare=False)
    #: what exists in the scenario (ground, targets, obstacles), from the sections
    world: World = field(default_factory=World, compare=False)
    #: the sections as written (YAML data), for ``resolved_dict``
    section_sources: dict[str, Any] = field(default_factory=dict, compare=False)
    schema_version: int = SCHEMA_VERSION
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def total_ticks(self) -> int:
        """Physics ticks in the run, rounded up to whole control exchanges (at least one)."""
        return total_ticks(self.duration_s, self.rates)

    @property
    def folder_name(self) -> str:
        """The name as a folder name (``runs/<folder_name>-<date>-<time>``): every
        character but letters, digits, ``_ . -`` becomes ``_``."""
        return safe_folder_name(self.name)

    @property
    def classes(self) -> tuple[str, ...]:
        """The vehicle classes of the run, in order of first appearance."""
        return tuple(dict.fromkeys(v.vehicle_class for v in self.vehicles))

    @property
    def channels(self) -> tuple[str, ...]:
        """Setpoint channels: each class's (its guidance's), then every JSBSim
        property the schedule writes, in first-use order."""
        seen: dict[str, None] = {}
        for name in self.classes:
            seen.update(dict.fromkeys(get_class(name).channels))
        for item in self.schedule:
            for name, _ in item.sets:
                seen.setdefault(name)
        return tuple(seen)

    def with_duration(self, duration_s: float) -> Scenario:
        import dataclasses

        return dataclasses.replace(self, duration_s=float(duration_s))

    def resolved_dict(self) -> dict[str, Any]:
        """A scenario document equivalent to this one with every vehicle listed
        (loads back to the same vehicles, bit for bit)."""
        vehicles = []
        for v in self.vehicles:
            cls = get_class(v.vehicle_class)
            d: dict[str, Any] = {"id": v.id, "class": v.vehicle_class}
            if v.model:
                d["model"] = v.model
            d["init"] = {"lat_deg": v.lat_deg, "lon_deg": v.lon_deg, "alt_msl_m": v.alt_msl_m,
                         "heading_deg": v.heading_deg, "airspeed_mps": v.airspeed_mps}
            if not v.trim and "trim" in cls.vehicle_keys:
                d["trim"] = False
            if v.initial_props and "set" in cls.vehicle_keys:
                d["set"] = dict(v.initial_props)
            d.update({k: v.class_params[k] for k in cls.vehicle_keys
                      if k not in ("trim", "set") and v.class_params.get(k) is not None})
            d["random_seed"] = v.random_seed
            vehicles.append(d)
        ids = [v.id for v in self.vehicles]
        return {
            "schema_version": self.schema_version,
            "name": self.name,
            "description": self.description,
            "origin": {"lat_deg": self.origin.lat_deg, "lon_deg": self.origin.lon_deg,
                       "ground_alt_m": self.origin.ground_alt_m},
            "rates": {"physics_hz": self.rates.physics_hz, "control_hz": self.rates.control_hz,
                      "log_hz": self.rates.log_hz},
            "duration_s": self.duration_s,
            "seed": self.seed,
            "aircraft_path": list(self.aircraft_path),
            "plot": self.plot,
            **({"mavlink": self.mavlink} if self.mavlink is not None else {}),
            "vehicles": vehicles,
            "schedule": [self._item_dict(s, ids) for s in self.schedule],
            **self.section_sources,
        }


    @staticmethod
    def _item_dict(s: ScheduleItem, ids: list[str]) -> dict[str, Any]:
        d: dict[str, Any] = {"at_s": s.at_s, "vehicles": [ids[i] for i in s.vehicles]}
        if s.sets:
            d["set"] = dict(s.sets)
        if s.command is not None:
            d["command"] = s.command.source
        return d


def safe_folder_name(name: str) -> str:
    """``name`` as one safe folder name: letters, digits and ``_ . -`` kept,
    everything else ``_``, no leading ``.``, at most ``MAX_NAME_CHARS``."""
    out = re.sub(r"[^A-Za-z0-9_.\-]", "_", name)[:lim.MAX_NAME_CHARS].lstrip(".")
    return out or "run"


def schedule_tick(at_s: float, rates: Rates) -> int:
    """The control tick at which an item at ``at_s`` applies (first at or after it)."""
    k = rates.control_every
    return math.ceil(round(at_s * rates.physics_hz, 6) / k) * k


def total_ticks(duration_s: float, rates: Rates) -> int:
    """Ticks in a run of ``duration_s``: rounded up to whole exchanges, at least one."""
    return max(rates.control_every, schedule_tick(duration_s, rates))
