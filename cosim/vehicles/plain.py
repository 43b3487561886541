"""The ``jsbsim`` class: any JSBSim model, flown by whatever its own systems
do. It takes no commands (a schedule may still write its JSBSim properties
with ``set:``); on MAVLink it is an ArduPlane in MANUAL that refuses modes.
The class of a model whose cosim profile names none."""

from __future__ import annotations

from cosim.vehicles.base import VehicleClass, on_mavlink


class PlainJSBSim(VehicleClass):
    name = "jsbsim"
    description = "any JSBSim model, flown by its own systems (set: properties; no commands)"
    model_kind = "jsbsim"
    mavlink = on_mavlink("cosim.vehicles.fixed_wing.mavlink:ARDUPLANE_NO_AUTOPILOT")


PLAIN = PlainJSBSim()
