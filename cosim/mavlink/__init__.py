"""mavlink: every simulated vehicle as an ordinary MAVLink vehicle.

Owns the MAVLink side of the simulation: vehicle identities (system ids,
modes, arming, parameters: what each class's personality says,
``personality``), telemetry built from the state array and stamped with
simulation time, one UDP socket for all vehicles, the microservices that
turn incoming messages into replies and commands in the command vocabulary
(``services``, routed by ``handlers``; ``cosim.guidance.commands``), and
``.tlog`` files.

It must not touch the pool, JSBSim or setpoints: it reads state rows and
returns ``Command`` values; the runner hands them to guidance. Only
``cosim.mavlink.adapter`` imports pymavlink.

Entry point: ``MavlinkEndpoint`` (see ``cosim.mavlink.endpoint``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

#: what the package exports, and the module each comes from: loaded on first
#: use, so that a vehicle class can import ``cosim.mavlink.personality`` (or the
#: adapter) without the endpoint, which imports the classes in turn
_EXPORTS = {
    "CONTROLLER_SYSID": "endpoint", "MAX_VEHICLES_PER_LINK": "endpoint",
    "MavlinkConfig": "endpoint", "MavlinkEndpoint": "endpoint", "VehicleCommand": "endpoint",
    "load_signing_key": "endpoint", "EndpointClosed": "errors", "LinkError": "errors",
    "LockstepTimeout": "errors", "MavlinkError": "errors", "DEFAULT_URL": "link",
    "LinkUrl": "link", "MavlinkLinks": "links", "link_specs": "links",
    "DEFAULT_RATES_HZ": "vehicle", "MavVehicleSpec": "vehicle", "SimClock": "vehicle",
    "mav_specs": "vehicle",
}
__all__ = ["CONTROLLER_SYSID", "DEFAULT_RATES_HZ", "DEFAULT_URL", "MAX_VEHICLES_PER_LINK",
           "EndpointClosed", "LinkError", "LinkUrl", "LockstepTimeout", "MavVehicleSpec",
           "MavlinkConfig", "MavlinkEndpoint", "MavlinkError", "MavlinkLinks", "SimClock",
           "VehicleCommand", "link_specs", "load_signing_key", "mav_specs"]

if TYPE_CHECKING:
    from cosim.mavlink.endpoint import (
        CONTROLLER_SYSID,
        MAX_VEHICLES_PER_LINK,
        MavlinkConfig,
        MavlinkEndpoint,
        VehicleCommand,
        load_signing_key,
    )
    from cosim.mavlink.errors import EndpointClosed, LinkError, LockstepTimeout, MavlinkError
    from cosim.mavlink.link import DEFAULT_URL, LinkUrl
    from cosim.mavlink.links import MavlinkLinks, link_specs
    from cosim.mavlink.vehicle import DEFAULT_RATES_HZ, MavVehicleSpec, SimClock, mav_specs


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'cosim.mavlink' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"cosim.mavlink.{module}"), name)
    globals()[name] = value
    return value
