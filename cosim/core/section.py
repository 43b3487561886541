"""The scenario-section contract: what a top-level section of a scenario file
(``swarm:``, ``cameras:``, ``search:``, ``targets:``, ... or one a package
adds through the ``cosim.sections`` entry-point group) declares, in one
object, as a vehicle class does (``cosim.vehicles.base.VehicleClass``).

A section says:

- its ``key`` in scenario files, and a one-line ``description``;
- ``parse(info, node, path)``: the section's node read into a frozen object
  (``Scenario.sections[key]``), every problem reported through ``info``
  with its path (the file line is found from it) and never raised;
- ``reads``: the sections whose parsed objects it reads (``info.sections``
  holds those, parsed before it; sections are ordered by these, not by
  their place in a list). It never changes another section's object;
- ``world(parsed)``: what it adds to the world (``cosim.world``): kind ->
  items, e.g. ``{"targets": (TargetSpec, ...)}`` (the search's fires);
- ``participant(scenario)``: the part it runs in the tick loop, if any
  (``cosim.sync.participants``), ``talks_mavlink`` if that part is a
  MAVLink client, and ``controller`` if it commands the swarm (so that
  ``--external-controller`` can run it in another process);
- ``outputs``: the files and folders its part writes in a run folder;
- ``one_core(parsed)``: its settings for a run given one core (each run of a
  sweep), e.g. rendering inline;
- ``sweep_tables``: functions ``table(result, spec)`` writing its tables of
  a finished sweep into ``result.out_dir`` (``cosim.sweep.runner``: the
  sweep's result, its runs, and its ``SweepSpec``);
- ``commands``: CLI commands it brings (``CliCommand``).

Sections are found by key (``scenario_sections``): cosim's own
(``BUILTIN_SECTIONS``) and any a package registers in the ``cosim.sections``
entry-point group, whose value is a ``Section`` instance (or a subclass,
instantiated here)::

    [project.entry-points."cosim.sections"]
    gusts = "my_package.gusts:GUSTS"

Nothing outside a section asks which section it is dealing with: the
scenario loader, the runner, the sweep and the CLI go through these. This
module is kernel: it imports nothing of cosim but ``cosim.core.plugins``
(the sections' own modules are loaded by name, when first asked for).
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Protocol

from cosim.core import plugins

log = logging.getLogger(__name__)

P = tuple[Any, ...]


class Reader(Protocol):
    """Typed access to one mapping of the file, reporting with lines
    (``SectionContext.reader``)."""

    d: dict[Any, Any]

    def has(self, key: str) -> bool: ...

    def num(self, key: str, default: Any = ..., lo: float | None = None,
            hi: float | None = None, lo_open: bool = False) -> Any: ...

    def integer(self, key: str, default: Any = ..., lo: int | None = None,
                hi: int | None = None) -> Any: ...

    def string(self, key: str, default: Any = ..., pattern: Any = None,
               choices: tuple[str, ...] | None = None) -> Any: ...

    def boolean(self, key: str, default: bool) -> bool: ...

    def one_of(self, *keys: str) -> str | None: ...


class SectionContext(Protocol):
    """What a section's parser sees (the scenario loader's ``SectionInfo``):
    the scenario parsed so far, the sections it ``reads``, and where to
    report problems."""

    origin: Any  # lat_deg, lon_deg, ground_alt_m, .frame (cosim.core.geo.LocalFrame)
    rates: Any  # physics_hz, control_hz, log_hz, control_every, dt_s
    duration_s: float
    vehicles: list[Any]  # cosim.core.state.VehicleSpec, in row order
    path: Path  # the scenario file (relative file names resolve against its folder)
    mavlink: dict[str, Any] | None  # the mavlink: section as resolved, or None
    seed: int
    sections: Mapping[str, Any]  # the parsed objects of the sections it reads

    @property
    def ids(self) -> list[str]: ...

    @property
    def problems(self) -> int: ...

    def err(self, path: P, msg: str) -> None: ...

    def reader(self, d: Any, path: P, allowed: tuple[str, ...]) -> Reader: ...

    def select(self, sel: Any, path: P) -> list[int]: ...


@dataclass(frozen=True)
class CliCommand:
    """A ``cosim`` subcommand (the CLI's own, or one a section brings):
    ``add_arguments(parser)`` declares its arguments, ``run(args) -> exit
    code`` does it (0 ok, 1 runtime failure, 2 usage or config error; a
    ``ConfigError`` it raises is printed and gives 2, another ``CosimError``
    or an ``OSError`` 1). Its module imports what the command needs inside
    ``run``, so ``cosim --help`` stays quick. ``rank`` places it in ``cosim
    --help`` (ascending; the CLI's own run from 10 to 120 in steps of 10, a
    command without one comes last). ``flies_aircraft``: it steps flight
    models in its own process, so ``cosim`` starts it with the physics
    allocator's settings (``cosim.core.memory.reexec_driver``)."""

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    epilog: str = ""
    rank: int = 1000
    flies_aircraft: bool = False


class Section:
    """One top-level scenario section (see the module docstring). Subclass
    it, set ``key`` and override what the section has."""

    key: str = ""
    description: str = ""
    #: the sections whose parsed objects ``parse`` reads (in ``info.sections``)
    reads: tuple[str, ...] = ()
    #: its participant is a MAVLink client of the run's links (in process)
    talks_mavlink: bool = False
    #: its participant commands the vehicles as the run's controller: with
    #: ``--external-controller`` it runs in another process instead
    controller: bool = False
    #: what its part writes in a run folder (files and folders, for the docs)
    outputs: tuple[str, ...] = ()
    #: ``table(result, spec)`` writers of a finished sweep's tables
    sweep_tables: tuple[Callable[[Any, Any], Any], ...] = ()
    #: CLI commands it brings
    commands: tuple[CliCommand, ...] = ()

    def parse(self, info: SectionContext, node: Any, path: P) -> Any:
        """The section's node read into a frozen object; problems go to ``info``."""
        raise NotImplementedError(f"section {self.key!r} has no parser")

    def world(self, parsed: Any) -> Mapping[str, Sequence[Any]]:
        """What the section adds to the world: kind (``targets``,
        ``obstacles``, ``ground``, ``sun``, ``atmosphere``) -> items. Default:
        nothing."""
        return {}

    def participant(self, scenario: Any) -> Any | None:
        """The part this section runs in the tick loop for ``scenario``, or
        None (``cosim.sync.participants`` says what a participant does)."""
        return None

    def one_core(self, parsed: Any) -> Any:
        """``parsed`` as a run given one core uses it (a sweep's runs fill the
        cores with whole runs). Default: unchanged."""
        return parsed


#: cosim's own sections, key -> "module:attribute" (the built-in twin of the
#: entry points a package declares)
BUILTIN_SECTIONS: dict[str, str] = {
    "swarm": "cosim.swarm.section:SWARM",
    "ground": "cosim.world.sections:GROUND",
    "targets": "cosim.world.sections:TARGETS",
    "cameras": "cosim.renderer.section:CAMERAS",
    "sweep": "cosim.sweep.section:SWEEP",
    "obstacles": "cosim.world.sections:OBSTACLES",
    "sun": "cosim.world.sections:SUN",
    "atmosphere": "cosim.world.sections:ATMOSPHERE",
    "search": "cosim.search.section:SEARCH",
}


@lru_cache(maxsize=1)
def scenario_sections() -> dict[str, Section]:
    """Every section by key, each after the sections it reads (a section
    reading one that does not exist, or a circle of them, is left out with a
    warning: a broken plug-in must not stop cosim)."""
    found: dict[str, Section] = {}
    for key, (obj, _) in plugins.load_instances(plugins.SECTIONS, BUILTIN_SECTIONS,
                                                Section).items():
        if obj.key != key:
            log.warning("cosim.sections entry %r is section %r: ignored", key, obj.key)
            continue
        found[key] = obj
    ordered: dict[str, Section] = {}
    state: dict[str, str] = {}

    def place(key: str, chain: tuple[str, ...]) -> bool:
        if key in ordered:
            return True
        if state.get(key) == "visiting":
            log.warning("cosim.sections: %s read each other: left out",
                        " -> ".join(chain + (key,)))
            return False
        state[key] = "visiting"
        for dep in found[key].reads:
            if dep not in found:
                log.warning("cosim.sections: section %r reads %r, which no package "
                            "provides: left out", key, dep)
                return False
            if not place(dep, chain + (key,)):
                return False
        ordered[key] = found[key]
        state[key] = "done"
        return True

    for key in found:
        place(key, ())
    return ordered


def get_section(key: str) -> Section:
    """The section called ``key``; ``ConfigError`` listing the others if none is."""
    return plugins.pick(plugins.SECTIONS, scenario_sections(), key,
                        ("scenario section", "sections"))
