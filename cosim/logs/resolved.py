"""What the commands use of a run's ``scenario.resolved.yaml``, read as
untrusted input: at most ``MAX_RESOLVED_BYTES``, through the scenario
loader's YAML reader (nesting, aliases, whole numbers; at most
``MAX_RESOLVED_VALUES`` values), then checked field by field, every problem
at once as ``file:line: path: message`` (a ``ConfigError``, exit 2).
``RunFolder.resolved`` finds the file (inside the run folder) and calls
``read_resolved``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeGuard

from cosim.core.geo import MAX_DISTANCE_M
from cosim.core.limits import MAX_NAME_CHARS, PHYSICS_HZ_RANGE
from cosim.errors import ConfigError, CosimError
from cosim.scenario.yaml_lines import YamlProblem, format_path, load_with_lines, read_text_bounded

#: ``scenario.resolved.yaml`` lists every vehicle: about 240 bytes and 11
#: values each (a 5001-vehicle run's is 1.2 MB), so 200,000 vehicles take
#: about 48 MB
MAX_RESOLVED_BYTES = 64 * 1024 * 1024
MAX_RESOLVED_VALUES = 5_000_000
RESOLVED = "scenario.resolved.yaml"


def is_number(v: Any) -> TypeGuard[int | float]:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _kind(model: str, vehicle_class: str | None, cache: dict[tuple[str, str | None], str]
          ) -> str:
    """The replay type (a class's ``display_type``) of a vehicle: its class's,
    else its model profile's class's; a name cosim cannot resolve (an older
    run's) gives the generic ``Air``."""
    from cosim.vehicles import DEFAULT_CLASS, get_class
    from cosim.vehicles.jsb import find_model

    key = (model, vehicle_class)
    if key not in cache:
        try:
            name = vehicle_class
            if name is None:
                name = find_model(model).profile.get("class", DEFAULT_CLASS)
            cache[key] = get_class(str(name)).display_type
        except (CosimError, OSError, ValueError):
            cache[key] = "Air"
    return cache[key]


@dataclass(frozen=True)
class RunVehicle:
    """A vehicle of a run as its resolved scenario lists it."""

    id: str
    model: str
    vehicle_class: str | None
    kind: str  # the class's replay type, e.g. "Air+FixedWing", "Ground+Vehicle"

    @property
    def on_ground(self) -> bool:
        return self.kind.startswith("Ground")


@dataclass(frozen=True)
class Resolved:
    """What the commands use of a run's ``scenario.resolved.yaml``."""

    name: str
    origin_lat_deg: float
    origin_lon_deg: float
    physics_hz: float | None
    vehicles: tuple[RunVehicle, ...]
    #: each obstacle's corners (north_m, east_m)
    obstacles: tuple[tuple[tuple[float, float], ...], ...]


class _Checker:
    """Problems of a YAML document, each as ``file:line: path: message``."""

    def __init__(self, where: Path, lines: dict[tuple[Any, ...], int]) -> None:
        self.where, self.lines = where, lines
        self.problems: list[str] = []

    def bad(self, path: tuple[Any, ...], message: str) -> None:
        p = path
        while p and p not in self.lines:
            p = p[:-1]
        self.problems.append(f"{self.where}:{self.lines.get(p, 1)}: {format_path(path)}: "
                             f"{message}")

    def text(self, d: dict[str, Any], key: str, path: tuple[Any, ...], limit: int,
             default: str | None = None) -> str | None:
        v = d.get(key, default)
        if v is None or (isinstance(v, str) and 0 < len(v) <= limit):
            return v
        self.bad(path + (key,), f"expected text of 1 to {limit} characters, got "
                                f"{show_value(v)}")
        return default

    def number(self, d: dict[str, Any], key: str, path: tuple[Any, ...], lo: float,
               hi: float, default: float | None) -> float | None:
        v = d.get(key, default)
        if v is None or (is_number(v) and lo <= v <= hi):
            return None if v is None else float(v)
        self.bad(path + (key,), f"expected a number from {lo:g} to {hi:g}, got {show_value(v)}")
        return default

    def mapping(self, d: dict[str, Any], key: str, path: tuple[Any, ...]) -> dict[str, Any]:
        v = d.get(key)
        if v is None or isinstance(v, dict):
            return v or {}
        self.bad(path + (key,), f"expected a mapping, got {show_value(v)}")
        return {}

    def listing(self, d: dict[str, Any], key: str, path: tuple[Any, ...]) -> list[Any]:
        v = d.get(key)
        if v is None or isinstance(v, list):
            return v or []
        self.bad(path + (key,), f"expected a list, got {show_value(v)}")
        return []


def show_value(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def read_resolved(p: Path, default_name: str) -> Resolved:
    """The resolved scenario at ``p`` (a path inside its run folder),
    checked; ``default_name``: its name when it gives none."""
    text = read_text_bounded(p, MAX_RESOLVED_BYTES, "resolved scenario",
                             "a resolved scenario")
    try:
        data, lines, _ = load_with_lines(text, MAX_RESOLVED_VALUES)
    except YamlProblem as e:
        raise ConfigError([f"{p}:{line}: {msg}" for line, msg in e.problems]) from None
    if not isinstance(data, dict):
        raise ConfigError(f"{p}:1: expected a resolved scenario (a mapping with "
                          f"vehicles:), got {show_value(data)}")
    c = _Checker(p, lines)
    origin = c.mapping(data, "origin", ())
    rates = c.mapping(data, "rates", ())
    vehicles: list[RunVehicle] = []
    kinds: dict[tuple[str, str | None], str] = {}
    seen: set[str] = set()
    for i, v in enumerate(c.listing(data, "vehicles", ())):
        path = ("vehicles", i)
        if not isinstance(v, dict):
            c.bad(path, f"expected a vehicle (a mapping with id:), got {show_value(v)}")
            continue
        vid = c.text(v, "id", path, MAX_NAME_CHARS)
        if vid is None:
            c.bad(path, "no id")
            continue
        if vid in seen:
            c.bad(path + ("id",), f"vehicle {vid!r} listed twice")
        seen.add(vid)
        model = c.text(v, "model", path, 200) or ""
        cls = c.text(v, "class", path, 200)
        vehicles.append(RunVehicle(vid, model or cls or "", cls, _kind(model, cls, kinds)))
    obstacles = []
    for i, o in enumerate(c.listing(data, "obstacles", ())):
        poly = _polygon(c, o, ("obstacles", i))
        if poly is not None:
            obstacles.append(poly)
    out = Resolved(
        name=c.text(data, "name", (), MAX_NAME_CHARS, "") or default_name,
        origin_lat_deg=c.number(origin, "lat_deg", ("origin",), -90, 90, 0.0) or 0.0,
        origin_lon_deg=c.number(origin, "lon_deg", ("origin",), -180, 180, 0.0) or 0.0,
        physics_hz=c.number(rates, "physics_hz", ("rates",), *PHYSICS_HZ_RANGE, None),
        vehicles=tuple(vehicles), obstacles=tuple(obstacles))
    if c.problems:
        raise ConfigError(c.problems)
    return out


def _polygon(c: _Checker, o: Any, path: tuple[Any, ...]
             ) -> tuple[tuple[float, float], ...] | None:
    if not isinstance(o, dict) or not isinstance(o.get("polygon"), list):
        c.bad(path, f"expected an obstacle with a polygon: list, got {show_value(o)}")
        return None
    pts = o["polygon"]
    ok = len(pts) >= 3 and all(
        isinstance(p, list) and len(p) == 2 and all(is_number(x) and abs(x) <= MAX_DISTANCE_M
                                                    for x in p) for p in pts)
    if not ok:
        c.bad(path + ("polygon",), f"expected 3 or more [north_m, east_m] corners within "
                                   f"{MAX_DISTANCE_M / 1000:g} km of the origin")
        return None
    return tuple((float(n), float(e)) for n, e in pts)
