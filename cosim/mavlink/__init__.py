"""mavlink: every simulated vehicle as an ordinary MAVLink vehicle.

Owns the MAVLink side of the simulation: vehicle identities (ArduPlane
system ids, modes, arming, parameters), telemetry built from the state
array and stamped with simulation time, one UDP socket for all vehicles,
the translation of incoming commands into the fixed-wing command vocabulary
(``cosim.guidance.commands``), and ``.tlog`` files.

It must not touch the pool, JSBSim or setpoints: it reads state rows and
returns ``Command`` values; the runner hands them to guidance. Only
``cosim.mavlink.adapter`` imports pymavlink.

Entry point: ``MavlinkEndpoint`` (see ``cosim.mavlink.endpoint``).
"""

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
from cosim.mavlink.vehicle import (
    DEFAULT_RATES_HZ,
    MavVehicleSpec,
    PlaneMode,
    SimClock,
    mav_specs,
)

__all__ = ["CONTROLLER_SYSID", "DEFAULT_RATES_HZ", "DEFAULT_URL", "MAX_VEHICLES_PER_LINK",
           "EndpointClosed", "LinkError", "LinkUrl", "LockstepTimeout", "MavVehicleSpec",
           "MavlinkConfig", "MavlinkEndpoint", "MavlinkError", "MavlinkLinks", "PlaneMode",
           "SimClock", "VehicleCommand", "link_specs", "load_signing_key", "mav_specs"]
