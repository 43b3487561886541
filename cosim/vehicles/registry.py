"""Vehicle classes by name: cosim's own (``fixed_wing``, ``jsbsim``) and any a
package registers in the ``cosim.vehicles`` entry-point group, whose value
is a ``VehicleClass`` instance (or a subclass, instantiated here)::

    [project.entry-points."cosim.vehicles"]
    my_rover = "my_package.rover:ROVER"

Worker processes find the same classes (they import the same packages).
"""

from __future__ import annotations

import logging
from functools import lru_cache

from cosim import plugins
from cosim.vehicles.base import VehicleClass

log = logging.getLogger(__name__)

#: a vehicle whose entry and model profile name no class
DEFAULT_CLASS = "jsbsim"


@lru_cache(maxsize=1)
def vehicle_classes() -> dict[str, VehicleClass]:
    """Every class by name, cosim's first."""
    out: dict[str, VehicleClass] = {}
    for name, p in plugins.load_plugins(plugins.VEHICLES).items():
        obj = p.obj() if isinstance(p.obj, type) else p.obj
        if not isinstance(obj, VehicleClass):
            log.warning("cosim.vehicles entry %r (%s) is not a VehicleClass: ignored", name,
                        p.source)
            continue
        if obj.name != name:
            log.warning("cosim.vehicles entry %r names class %r: registered as %r", name,
                        obj.name, name)
        out[name] = obj
    return out


def get_class(name: str) -> VehicleClass:
    """The class called ``name``; ``ConfigError`` listing the others if none is."""
    return plugins.pick(plugins.VEHICLES, vehicle_classes(), name,
                        ("vehicle class", "classes"))
