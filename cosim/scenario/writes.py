"""Raw property writes (a vehicle's ``set:``, the schedule's): as the
vehicle's class allows them (nothing that moves a vehicle by decree), and
each property existing and writable in the model (JSBSim silently creates a
misspelled one and ignores a write to a read-only one)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from cosim.core.state import VehicleSpec
from cosim.scenario.model import ScheduleItem
from cosim.scenario.reader import P, Problems
from cosim.vehicles import get_class
from cosim.vehicles.jsb import has_property, is_writable, new_fdm


def check_writes(ctx: Problems, vehicles: list[tuple[VehicleSpec, P]],
                  schedule: list[ScheduleItem]) -> None:
    """Every raw property write (a vehicle's ``set:``, a schedule item's) as
    the vehicle's class allows it (``VehicleClass.write_problems``: nothing
    that moves a vehicle by decree or bypasses the rule of the commands)."""
    def check(where: P, specs: list[VehicleSpec], props: Sequence[tuple[str, float]]) -> None:
        for name, value in props:
            said: set[str] = set()
            for spec in specs:
                for problem in get_class(spec.vehicle_class).write_problems(name, value, spec):
                    if problem not in said:
                        said.add(problem)
                        ctx.err(where + (name,), problem)

    done: set[P] = set()
    for spec, vp in vehicles:
        if spec.initial_props and vp not in done:
            done.add(vp)
            check(vp + ("set",), [spec], spec.initial_props)
    specs = [v for v, _ in vehicles]
    for item in schedule:
        if item.sets:
            check(("schedule", item.index, "set"), [specs[j] for j in item.vehicles], item.sets)


def check_property_names(ctx: Problems, vehicles: list[tuple[VehicleSpec, P]],
                      schedule: list[ScheduleItem], fdms: dict[tuple[str, str], Any]) -> None:
    """Every property written must exist, and be writable, in every model it is
    written to (JSBSim silently creates misspelled properties and silently
    ignores writes to read-only ones). ``fdms``: one FDM of each model, built
    when first needed (kept by the caller: only read, never stepped)."""

    def fdm_of(spec: VehicleSpec) -> Any:
        key = (spec.model, spec.aircraft_dir)
        if key not in fdms:
            from cosim.vehicles.jsb import ModelInfo

            fdms[key] = new_fdm(ModelInfo(spec.model, spec.aircraft_dir, spec.model_source,
                                          profile=spec.profile), 0.01)
        return fdms[key]

    def exists(spec: VehicleSpec, name: str) -> bool:
        return has_property(fdm_of(spec), name)

    def writable(spec: VehicleSpec, name: str) -> bool:
        return is_writable(fdm_of(spec), name)

    def check(where: P, specs: list[VehicleSpec], props: list[tuple[str, float]],
              report: Callable[[P, str], None]) -> None:
        known = {id(s): get_class(s.vehicle_class).writable_properties(s) for s in specs}
        own = [s for s in specs if known[id(s)] is not None]
        specs = [s for s in specs if known[id(s)] is None]  # JSBSim models: ask JSBSim
        for name, _ in props:  # a class that knows its inputs
            for cls, model in sorted({(s.vehicle_class, s.model) for s in own
                                      if name not in (known[id(s)] or ())}):
                names = sorted(get_class(cls).writable_properties(
                    next(s for s in own if s.vehicle_class == cls and s.model == model)) or ())
                shown = ", ".join(names[:12]) + (f" and {len(names) - 12} more"
                                                 if len(names) > 12 else "")
                report(where + (name,), f"{name!r} is not an input of class {cls} (model "
                                        f"{model}; its inputs: {shown or 'none'})")
        for name, value in props:
            if any(get_class(s.vehicle_class).write_problems(name, value, s) for s in specs):
                continue  # refused already (``check_writes``)
            missing = sorted({s.model for s in specs if not exists(s, name)})
            if missing:
                report(where + (name,), f"JSBSim property {name!r} does not exist in model "
                                        f"{', '.join(missing)} (check the spelling; "
                                        f"`cosim models --properties MODEL` lists them)")
                continue
            read_only = sorted({s.model for s in specs if not writable(s, name)})
            if read_only:
                report(where + (name,), f"JSBSim property {name!r} is read-only in model "
                                        f"{', '.join(read_only)}: JSBSim would ignore the "
                                        f"value (`cosim models --properties MODEL` marks "
                                        f"writable ones RW)")

    done: set[P] = set()
    for spec, vp in vehicles:
        if spec.initial_props and vp not in done:
            done.add(vp)
            check(vp + ("set",), [spec], list(spec.initial_props), ctx.err)
    specs = [v for v, _ in vehicles]
    for item in schedule:
        check(("schedule", item.index, "set"), [specs[j] for j in item.vehicles],
              list(item.sets), ctx.err)
