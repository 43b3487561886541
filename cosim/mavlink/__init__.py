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
``cosim.mavlink.adapter`` imports pymavlink. It builds on the kernel alone
(``cosim.core``, ``cosim.errors``, ``cosim.guidance``): each vehicle class
hands down its personality and safety rule (``vehicle.MavClass``), the
scenario loader calls the ``mavlink:`` section's parser
(``cosim.mavlink.scenario``).

Entry points: ``MavlinkEndpoint`` (one link, ``endpoint``) and
``MavlinkLinks`` (a run's links, 240 vehicles each, ``links``), configured
by ``MavlinkConfig`` (``config``). The endpoint drives ``inbox`` (datagrams
decoded, signatures checked), ``lockstep`` (an outside controller),
``router`` (each message to its vehicles), ``handlers`` and ``services``
(the microservices), ``outbox`` (packets to peers, in-process clients and
tlogs) and ``telemetry`` (the streams). A vehicle (``vehicle``) has its
parameters (``params``), its missions (``mission``, flown by
``mission_runner``, fenced by ``fence``) and its class's ``personality``
(``ardupilot``: what ArduPilot-like classes share); every answer is an
``outcome``. Below them: ``adapter`` (pymavlink), ``batch`` (telemetry
encoded for many vehicles at once), ``link`` (the socket and its peers),
``signing`` (replay protection shared by links and runs), ``tlog``.
"""

from __future__ import annotations

from cosim.mavlink.config import MavlinkConfig, load_signing_key
from cosim.mavlink.endpoint import CONTROLLER_SYSID, MAX_VEHICLES_PER_LINK, MavlinkEndpoint
from cosim.mavlink.errors import EndpointClosed, LinkError, LockstepTimeout, MavlinkError
from cosim.mavlink.link import DEFAULT_URL, LinkUrl
from cosim.mavlink.links import MavlinkLinks, link_specs
from cosim.mavlink.router import VehicleCommand
from cosim.mavlink.vehicle import DEFAULT_RATES_HZ, MavVehicleSpec, SimClock, mav_specs

__all__ = ["CONTROLLER_SYSID", "DEFAULT_RATES_HZ", "DEFAULT_URL", "MAX_VEHICLES_PER_LINK",
           "EndpointClosed", "LinkError", "LinkUrl", "LockstepTimeout", "MavVehicleSpec",
           "MavlinkConfig", "MavlinkEndpoint", "MavlinkError", "MavlinkLinks", "SimClock",
           "VehicleCommand", "link_specs", "load_signing_key", "mav_specs"]
