"""vehicles: the vehicle classes (an extension point) and their models.

Owns the class protocol (``base.VehicleClass``; a vehicle's spec and the
state array's layout are the kernel's, ``cosim.core.state``), JSBSim's
plumbing and the aircraft catalog (``jsb``), the registry of classes (``registry``:
cosim's own and any a package registers in the ``cosim.vehicles`` entry-point
group), the model kinds (JSBSim-backed: ``jsbsim_model``; batched:
``base.BatchedModel``) and cosim's classes: ``fixed_wing`` (an ArduPlane-like
fixed-wing with cosim's autopilot) and ``jsbsim`` (any JSBSim model, flown
by whatever its own systems do). Nothing outside this package asks which
class a vehicle is: it asks the class.
"""

from cosim.vehicles.base import (
    BatchedModel,
    Guidance,
    GuidanceEvent,
    ModelChoice,
    VehicleClass,
)
from cosim.vehicles.registry import DEFAULT_CLASS, get_class, state_layout, vehicle_classes

__all__ = ["DEFAULT_CLASS", "BatchedModel", "Guidance", "GuidanceEvent", "ModelChoice",
           "VehicleClass", "get_class", "state_layout", "vehicle_classes"]
