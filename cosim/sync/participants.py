"""Participants: parts that run inside the lockstep loop beside the pool
(the swarm controller, the cameras), each owned by its own package.

A scenario section whose ``Section.participant(scenario)`` gives one
(``cosim.core.section``) makes the runner run it, in the sections' order
(each after the sections it reads). Per run:

- ``prepare(ctx)`` (optional) once, before any participant starts: e.g. to
  add a tap on the camera frames (``ctx.frame_taps``);
- ``start(ctx)`` once, after the vehicles are built, before the first tick;
- ``before_step(tick, states, setpoints)`` (optional) at every exchange,
  before the pool's step from ``tick``: after the schedule's and MAVLink's
  commands, before guidance follows them, in participant order. For commands
  of the participant's own (``cosim.sync.inbox.CommandInbox``: an
  operator's), given through ``ctx.commander.command`` like every other
  source's; ``states`` is the state array at ``tick`` (read only);
- ``on_exchange(tick, states)`` at every exchange, after the schedule,
  MAVLink commands and guidance, once the pool's step from ``tick`` has
  started (``pool.send``) and the telemetry due at ``tick`` has been sent:
  it runs while the workers step; ``states`` is a copy of the state array
  at ``tick`` (do not keep it past the call). A controller commands vehicles
  by injecting MAVLink messages (``ctx.mavlink.inject(message, link)``): the
  endpoint handles them at the next exchange, exactly like a ground
  station's;
- ``finish(tick, reason)`` once, whatever the end (also after an error);
  returns the participant's section of ``summary.json`` (or None; an
  ``"error"`` in it marks the run's outputs incomplete). A
  participant that failed (at start, in the loop, or as it finishes) raises
  ``ParticipantFailed`` here with its section: the run then ends as an
  error, with one ``error`` event, and the section is still in the summary.
  An exception from ``start`` or ``on_exchange`` ends the loop at once.
- ``after_run(out_dir)`` after ``summary.json`` is written (plots); errors
  there are logged, never lose the run.

A participant that needs some vehicles' states more often than the
exchanges (a camera's aircraft at its frame rate) says so before the
vehicles are built with ``watch_requests()`` -> ``[(row, every ticks)]``;
the pool then gathers those rows inside each exchange and
``ctx.watched`` holds them after it (only those few vehicles pay for it).

Participants must not touch the pool, the logs' files or each other; results
must not depend on the backend or the worker count.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from cosim.errors import CosimError

if TYPE_CHECKING:
    from cosim.core.geo import LocalFrame
    from cosim.logs import EventLog
    from cosim.scenario import Scenario

class ParticipantFailed(CosimError):
    """A participant failed: ``error`` says what (naming what failed, e.g. the
    camera and vehicle), ``section`` is its part of ``summary.json`` anyway."""

    def __init__(self, error: BaseException, section: dict[str, Any] | None = None) -> None:
        super().__init__(error, section)
        self.error = error
        self.section = section

    def __str__(self) -> str:
        return str(self.error)


@dataclass
class RunContext:
    """What a participant may use during a run."""

    scenario: Scenario
    out_dir: Path
    ids: list[str]
    frame: LocalFrame  # the scenario's local WGS-84 NED frame
    start_ned_m: np.ndarray  # (n, 3) each vehicle's start in ``frame``
    physics_hz: float
    control_every: int  # ticks per exchange
    events: EventLog  # ``events.emit(kind, tick, vehicle=..., **fields)``
    mavlink: Any  # the run's cosim.mavlink.MavlinkLinks (None: no MAVLink)
    workers: int  # the pool's worker count (for parts with their own pools)
    #: the run's cosim.sync.commands.Commander: ``commander.observers`` hear
    #: every command, from every source (None: a context outside a run)
    commander: Any = None
    #: who wants the camera frames the cameras render (the live view, video
    #: streams): ``(tap, width_px)`` pairs, ``tap(vehicle, camera, time_s, bgr)``
    #: called with each frame scaled to at most ``width_px`` wide (None: full
    #: size); filled before any participant starts, so the cameras know
    frame_taps: list[Any] | None = None
    #: ``gimbal_angles(vehicle_id, camera_name)``: a gimbal camera's
    #: ``(pitch_deg, yaw_deg)`` as the cameras last posed it (commands and
    #: ``look_at`` tracking included; None: not a camera on a gimbal); set by
    #: the cameras when they start (None: a run without cameras)
    gimbal_angles: Any = None
    #: the states gathered inside the last exchange for the rows participants
    #: asked for (``watch_requests``); None: nobody asked
    watched: WatchedStates | None = None
    #: the state array's column names (``STATE_FIELDS``, then those the
    #: run's vehicle classes add, such as ``fuel_kg``); empty outside a run
    columns: tuple[str, ...] = ()
    #: how long a worker process of a participant (a render worker) may be silent
    #: while it has work, as the pool's workers (``--step-timeout-s``)
    step_timeout_s: float = 60.0


@dataclass
class WatchedStates:
    """The rows a participant asked to see more often than the exchanges
    (``watch_requests``): their states at ``ticks`` inside the last
    exchange, ``states[chunk, position of the row in rows]``; the last
    chunk is the exchange's own tick. Refreshed after every exchange."""

    rows: tuple[int, ...]
    ticks: list[int]
    states: np.ndarray


def watch_for(participants: list[Any], control_every: int) -> tuple[tuple[int, ...], int] | None:
    """What the participants ask to be gathered between exchanges: the rows,
    and every how many ticks (the greatest common divisor of their rates, a
    divisor of ``control_every``), or None. A participant asks with an
    optional ``watch_requests()`` -> ``[(row, every), ...]``."""
    import math

    reqs = [r for p in participants for r in getattr(p, "watch_requests", list)()]
    if not reqs:
        return None
    every = 0
    for _, e in reqs:
        every = math.gcd(every, int(e))
    if control_every % every:
        raise CosimError(f"rows asked for every {every} ticks cannot be gathered inside "
                         f"exchanges of {control_every} ticks")
    return tuple(sorted({int(r) for r, _ in reqs})), every


class Participant(Protocol):
    name: str

    def start(self, ctx: RunContext) -> None: ...

    # optional: ``before_step(tick, states, setpoints) -> None`` (module docstring)

    def on_exchange(self, tick: int, states: np.ndarray) -> None: ...

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None: ...

    def after_run(self, out_dir: Path) -> None: ...


def needs_mavlink(scenario: Scenario) -> bool:
    """True if a section of the scenario runs a MAVLink client (the swarm
    controller, the search's missions)."""
    return any(sec.talks_mavlink for sec in _sections_of(scenario))


def has_controller(scenario: Scenario) -> bool:
    """True if a section of the scenario commands its vehicles as the run's
    controller (what ``--external-controller`` runs in another process)."""
    return any(sec.controller for sec in _sections_of(scenario))


def build_participants(scenario: Scenario, external_controller: bool = False
                       ) -> list[Participant]:
    """The participants the scenario's sections run, in the sections' order;
    with ``external_controller``, not the controller's (it runs elsewhere)."""
    out: list[Participant] = []
    for sec in _sections_of(scenario):
        if external_controller and sec.controller:
            continue
        part = sec.participant(scenario)
        if part is not None:
            out.append(part)
    return out


def _sections_of(scenario: Scenario) -> list[Any]:
    from cosim.core.section import scenario_sections

    return [sec for key, sec in scenario_sections().items() if key in scenario.sections]
