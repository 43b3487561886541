"""Extension points: what other packages may add to cosim, found by name.

Three Python entry-point groups, each with cosim's own entries built in:

- ``cosim.backends``: pool backends (``cosim.fdm_pool.backends``; cosim's
  own are listed here, ``BUILTIN_BACKENDS``, so that ``cosim --help`` can
  name them without importing the pool package);
- ``cosim.vehicles``: vehicle classes (``cosim.vehicles``; cosim's own are
  listed by the vehicles package itself, ``cosim.vehicles.registry``);
- ``cosim.sections``: scenario sections (``cosim.core.section``; cosim's own
  are listed by the scenario package, ``cosim.scenario.sections``).

A package adds an entry in its ``pyproject.toml``::

    [project.entry-points."cosim.vehicles"]
    my_rover = "my_package.rover:ROVER"

This module only finds and loads entries; what an entry must be is said by
the part that uses it. It imports nothing heavy, so ``cosim --help`` can list
names without loading anything.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, TypeVar

from cosim.errors import ConfigError

log = logging.getLogger(__name__)

BACKENDS = "cosim.backends"
VEHICLES = "cosim.vehicles"
SECTIONS = "cosim.sections"
#: the backend ``cosim run`` uses unless told otherwise
DEFAULT_BACKEND = "process"

#: cosim's own backends, name -> "module:attribute"
BUILTIN_BACKENDS: dict[str, str] = {
    "inline": "cosim.fdm_pool.inline:InlinePool",
    "process": "cosim.fdm_pool.process:ProcessPool",
    "ray": "cosim.fdm_pool.ray_cluster:RayPool",
}


T = TypeVar("T")


@dataclass(frozen=True)
class Plugin:
    name: str
    obj: Any
    source: str  # "cosim" or the distribution (else the entry point's value)


def plugin_names(group: str, builtin: Mapping[str, str]) -> list[str]:
    """Every entry's name in ``group``, cosim's own (``builtin``: name ->
    "module:attribute") first, without loading any."""
    names = list(builtin)
    names += [ep.name for ep in entry_points(group=group) if ep.name not in names]
    return names


def load_plugins(group: str, builtin: Mapping[str, str]) -> dict[str, Plugin]:
    """Every entry of ``group`` loaded, cosim's first. An entry whose name repeats
    an earlier one is ignored, one that fails to load is skipped; both with a
    warning (a broken plug-in must not stop cosim)."""
    out: dict[str, Plugin] = {}
    for name, target in builtin.items():
        module, attr = target.split(":")
        out[name] = Plugin(name, getattr(importlib.import_module(module), attr), "cosim")
    for ep in entry_points(group=group):
        if ep.name in out:
            log.warning("%s entry %r (%s) repeats a name: ignored", group, ep.name, ep.value)
            continue
        try:
            obj = ep.load()
        except Exception as e:
            log.warning("%s entry %r (%s) cannot be loaded: %s: %s", group, ep.name,
                        ep.value, type(e).__name__, e)
            continue
        dist = getattr(ep, "dist", None)
        out[ep.name] = Plugin(ep.name, obj, getattr(dist, "name", None) or ep.value)
    return out


def load_instances(group: str, builtin: Mapping[str, str], kind: type[T]
                   ) -> dict[str, tuple[T, str]]:
    """``load_plugins``' entries that are a ``kind`` (a subclass of it is
    instantiated), each with where it came from; any other is skipped with a
    warning."""
    out: dict[str, tuple[T, str]] = {}
    for name, p in load_plugins(group, builtin).items():
        obj = p.obj() if isinstance(p.obj, type) else p.obj
        if not isinstance(obj, kind):
            log.warning("%s entry %r (%s) is not a %s: ignored", group, name, p.source,
                        kind.__name__)
            continue
        out[name] = (obj, p.source)
    return out


def pick(group: str, loaded: Mapping[str, T], name: str, what: tuple[str, str]) -> T:
    """The entry ``name`` of ``loaded`` (``group``'s entries as the part using
    them made them); ``ConfigError`` naming the others if there is none.
    ``what``: what an entry is, singular and plural."""
    found = loaded.get(name)
    if found is None:
        raise ConfigError(f"unknown {what[0]} {name!r}; available: {', '.join(loaded)} "
                          f"(packages add {what[1]} in the {group!r} entry-point group)")
    return found
