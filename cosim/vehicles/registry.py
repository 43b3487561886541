"""Vehicle classes by name: cosim's own (``fixed_wing``, ``jsbsim``) and any a
package registers in the ``cosim.vehicles`` entry-point group, whose value
is a ``VehicleClass`` instance (or a subclass, instantiated here)::

    [project.entry-points."cosim.vehicles"]
    my_rover = "my_package.rover:ROVER"

Worker processes find the same classes (they import the same packages).
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Sequence
from functools import cache, lru_cache

from cosim.core import plugins
from cosim.core.state import STATE_FIELDS, StateField, VehicleSpec
from cosim.vehicles.base import VehicleClass

log = logging.getLogger(__name__)

#: a vehicle whose entry and model profile name no class
DEFAULT_CLASS = "jsbsim"
#: cosim's own classes, name -> "module:attribute" (the built-in twin of the
#: entry points a package declares)
BUILTIN_CLASSES: dict[str, str] = {
    "fixed_wing": "cosim.vehicles.fixed_wing:FIXED_WING",
    "jsbsim": "cosim.vehicles.plain:PLAIN",
    "ground": "cosim.vehicles.ground:GROUND",
    "quadrotor": "cosim.vehicles.quadrotor:QUADROTOR",
    "fixed_wing_batched": "cosim.vehicles.fixed_wing_batched:FIXED_WING_BATCHED",
    "fixed_wing_rigid": "cosim.vehicles.fixed_wing_rigid:FIXED_WING_RIGID",
}


@lru_cache(maxsize=1)
def vehicle_classes() -> dict[str, VehicleClass]:
    """Every class by name, cosim's first."""
    out: dict[str, VehicleClass] = {}
    for name, (obj, _) in plugins.load_instances(plugins.VEHICLES, BUILTIN_CLASSES,
                                                 VehicleClass).items():
        if obj.name != name:
            log.warning("cosim.vehicles entry %r names class %r: registered as %r", name,
                        obj.name, name)
        out[name] = obj
    return out


def get_class(name: str) -> VehicleClass:
    """The class called ``name``; ``ConfigError`` listing the others if none is.
    One of cosim's own is imported alone (an entry point cannot replace it): a
    physics worker imports only its vehicles' classes."""
    if name in BUILTIN_CLASSES:
        return _builtin(name)
    return plugins.pick(plugins.VEHICLES, vehicle_classes(), name,
                        ("vehicle class", "classes"))


@cache
def _builtin(name: str) -> VehicleClass:
    module, attr = BUILTIN_CLASSES[name].split(":")
    obj: VehicleClass = getattr(importlib.import_module(module), attr)
    return obj


def state_layout(specs: Sequence[VehicleSpec]) -> tuple[StateField, ...]:
    """The state array's columns for these vehicles: ``STATE_FIELDS``, then
    the columns each of their classes adds, in order of first appearance (a
    name two classes share is one column)."""
    fields = list(STATE_FIELDS)
    names = {f.name for f in fields}
    for cls_name in dict.fromkeys(s.vehicle_class for s in specs):
        for f in get_class(cls_name).state_columns:
            if f.name not in names:
                names.add(f.name)
                fields.append(f)
    return tuple(fields)
