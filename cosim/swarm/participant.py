"""The swarm controller inside ``cosim run``: telemetry by ``subscribe``,
commands by ``inject`` (no socket), metrics from the ground truth.

At every exchange (``on_exchange(tick)``, right after the endpoint sent the
telemetry due at ``tick``): the monitor takes the true positions, then at a
controller step the controller acts on the telemetry received so far; its
injected commands are handled at the next exchange. Phase and separation
events go to ``events.jsonl``; ``summary.json["swarm"]`` gets the phases with
their metrics; ``after_run`` writes ``swarm.png``, ``swarm_commands.csv``
(every command: tick, vehicle, speed sent, stall speed, roll, altitude) and
``swarm_separation.csv`` (the closest pair at every exchange).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.scenario import Scenario
from cosim.swarm.config import SwarmSpec
from cosim.swarm.controller import SwarmController, to_message
from cosim.swarm.metrics import SwarmMonitor
from cosim.sync.participants import RunContext

log = logging.getLogger(__name__)
_S = STATE_INDEX


def merged_summary(ctl: SwarmController, mon: SwarmMonitor) -> dict[str, Any]:
    """The controller's phases (telemetry) joined with the monitor's metrics."""
    out = ctl.summary()
    ms = mon.summary()
    for name, g in out["groups"].items():
        metrics = ms["phases"].get(name, [])
        for rec, met in zip(g["phases"], metrics):
            rec.update({k: v for k, v in met.items() if k not in rec})
        for rec in g["phases"]:
            rec["converged"] = rec.get("reason") == "converged"
    out.update({k: v for k, v in ms.items() if k != "phases"})
    return out


def write_commands_csv(path: Path, ctl: SwarmController, physics_hz: float) -> None:
    with open(path, "w") as f:
        f.write("tick,t_s,vehicle,speed_mps,stall_mps,roll_rad,alt_msl_m\n")
        for tick, i, spd, stall, roll, alt in ctl.sent:
            f.write(f"{tick},{tick / physics_hz:.4f},{ctl.ids[i]},{spd!r},{stall!r},{roll!r},"
                    f"{alt!r}\n")


def write_swarm_outputs(out_dir: Path, ctl: SwarmController, mon: SwarmMonitor,
                        title: str) -> None:
    """``swarm_commands.csv``, ``swarm_separation.csv`` and ``swarm.png`` (in-process
    and ``cosim swarm --connect`` alike)."""
    write_commands_csv(out_dir / "swarm_commands.csv", ctl, mon.hz)
    mon.write_separation_csv(out_dir / "swarm_separation.csv")
    if mon.track_ticks:
        from cosim.swarm.plot import plot_swarm

        p = plot_swarm(out_dir / "swarm.png", ctl.spec, [g.idx for g in ctl.groups],
                       mon.track_ticks, mon.track_pos, mon.track_phase, mon.hz, title)
        log.info("swarm plot: %s", p)


class SwarmParticipant:
    name = "swarm"

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        spec = scenario.sections["swarm"]
        assert isinstance(spec, SwarmSpec)
        self.spec = spec
        self.ctx: RunContext | None = None
        self.ctl: SwarmController | None = None
        self.mon: SwarmMonitor | None = None

    def start(self, ctx: RunContext) -> None:
        if ctx.mavlink is None:
            raise RuntimeError("swarm: the run has no MAVLink endpoint (the runner makes one "
                               "for a swarm: section)")
        self.ctx = ctx
        scn = self.scenario
        on_mav = {v.row for specs in ctx.mavlink.specs for v in specs}
        off = [scn.vehicles[r].id for r in self.spec.rows if r not in on_mav]
        if off:  # (validation refuses such a scenario; a --mavlink override cannot add it)
            raise RuntimeError(f"swarm: vehicles {', '.join(off[:5])} are not on MAVLink")
        # the run's cosim.mavlink.MavlinkLinks: subscribe callbacks get (message,
        # link), inject takes the link (one link per 240 vehicles)
        self.ctl = SwarmController(self.spec, scn.vehicles, ctx.frame, ctx.physics_hz,
                                   links=ctx.mavlink.specs)
        self.mon = SwarmMonitor(self.spec, self.ctl.ids, [g.idx for g in self.ctl.groups],
                                ctx.physics_hz)
        self.rows = self.ctl.rows
        ctx.mavlink.subscribe(self.ctl.on_message)

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        ctx, ctl, mon = self.ctx, self.ctl, self.mon
        assert ctx is not None and ctl is not None and mon is not None
        s = states[self.rows]
        n, e, d = ctx.frame.geodetic_to_ned(s[:, _S["lat_deg"]], s[:, _S["lon_deg"]],
                                            s[:, _S["alt_msl_m"]])
        mon.update(tick, np.stack([n, e, d], axis=1))
        if ctl.due(tick):
            for o in ctl.step(tick):
                ctx.mavlink.inject(to_message(o), o.link)
        self._flush_events()

    def _flush_events(self) -> None:
        ctx, ctl, mon = self.ctx, self.ctl, self.mon
        assert ctx is not None and ctl is not None and mon is not None
        for kind, tick, fields in ctl.drain_events():
            mon.phase_event(tick, fields)
            ctx.events.emit(kind, tick, vehicle=None, **fields)
        for kind, tick, fields in mon.drain_events():
            ctx.events.emit(kind, tick, vehicle=None, **fields)

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        if self.ctl is None or self.mon is None:
            return None
        self.ctl.end_run(tick)
        self._flush_events()  # the phases still running end with reason run_end
        return merged_summary(self.ctl, self.mon)

    def after_run(self, out_dir: Path) -> None:
        if self.ctl is not None and self.mon is not None:
            write_swarm_outputs(out_dir, self.ctl, self.mon, self.scenario.name)
