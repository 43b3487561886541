"""The ``schedule:`` section: timed ``set:`` writes and commands for chosen
vehicles, each command checked as its vehicles' class allows it at that
point of the schedule (the model's envelope, the rule of every command path)."""

from __future__ import annotations

from typing import Any

from cosim.core.state import VehicleSpec
from cosim.guidance import DEFAULT_BANK_LIMIT_DEG, parse_command
from cosim.guidance.safety import Limits, speed_after
from cosim.scenario.model import Rates, ScheduleItem, schedule_tick, total_ticks
from cosim.scenario.reader import P, Problems, Reader, describe, prop_values, select
from cosim.vehicles import get_class


def parse_schedule(ctx: Problems, d: Any, vehicles: list[tuple[VehicleSpec, P]], rates: Rates,
              duration: float) -> list[ScheduleItem]:
    if not isinstance(d, list):
        ctx.err(("schedule",), f"expected a list of timed actions, got {describe(d)}")
        return []
    ids = [v.id for v, _ in vehicles]
    out = []
    k = rates.control_every
    total = total_ticks(duration, rates)  # Scenario.total_ticks
    for i, sd in enumerate(d):
        sp: P = ("schedule", i)
        r = Reader(ctx, sd, sp, ("at_s", "vehicles", "set", "command"))
        at = r.num("at_s", lo=0)
        if at is not None and schedule_tick(at, rates) >= total:
            ctx.err(sp + ("at_s",), f"at_s {at:g} is at or after the end of the run (duration_s "
                                    f"{duration:g}), so it would never run; the last control "
                                    f"exchange starts at {(total - k) / rates.physics_hz:g} s")
        sel = select(ctx, r.d.get("vehicles", "all"), sp + ("vehicles",), ids)
        if not r.has("set") and not r.has("command"):
            ctx.err(sp, "missing 'set' (JSBSim property: value) or 'command' (heading_deg, "
                        "alt_msl_m, airspeed_kt, goto, waypoints, loiter, ...)")
            continue
        sets = prop_values(ctx, r.d["set"], sp + ("set",)) if r.has("set") else []
        cmd = parse_command(r.d["command"], sp + ("command",), ctx.err) if r.has(
            "command") else None
        if at is None or (r.has("command") and cmd is None):
            continue
        out.append(ScheduleItem(at, schedule_tick(at, rates), tuple(sel), tuple(sets), i, cmd))
    out.sort(key=lambda s: s.tick)  # stable: file order within a tick
    _check_commands(ctx, out, [v for v, _ in vehicles])
    return out


def _check_commands(ctx: Problems, schedule: list[ScheduleItem], specs: list[VehicleSpec]) -> None:
    """Commands only for vehicles whose class takes them, and each as its class
    allows at that point of the schedule (``VehicleClass.command_problems``:
    the model's envelope, then the rule of every command path, with the speed
    and bank limit in force)."""
    speed = [v.airspeed_mps for v in specs]
    bank = [DEFAULT_BANK_LIMIT_DEG] * len(specs)
    for item in schedule:
        cmd = item.command
        if cmd is None or not cmd.flies:  # gimbal angles are for the cameras
            continue
        path: P = ("schedule", item.index, "command")
        mute = sorted({(specs[j].model, specs[j].vehicle_class) for j in item.vehicles
                       if not get_class(specs[j].vehicle_class).commandable})
        if mute:
            ctx.err(path, "; ".join(f"model {m} (class {c}) takes no commands" for m, c in mute)
                    + " (fixed-wing profiles: aircraft/profiles/, aircraft/<model>/cosim.yaml)")
            continue
        for j in item.vehicles:
            vc = get_class(specs[j].vehicle_class)
            lim = Limits(specs[j].terrain_alt_m, vc.min_alt_agl_m(specs[j].profile), speed[j],
                         bank[j])
            if cmd.bank_limit_deg is not None:
                bank[j] = cmd.bank_limit_deg
            speed[j] = speed_after(cmd, speed[j])
            problems = vc.command_problems(cmd, specs[j], lim)
            for problem in problems:
                ctx.err(path, problem)
            if problems:
                break
