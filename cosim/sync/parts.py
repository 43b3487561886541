"""The runner's own participants: each does one job at its point of an
exchange, so the tick loop itself only calls them in order (see
``cosim.sync.runner``).

An exchange at tick T::

    before the step   Schedule (set:/command: items due), MavlinkPart
                      (receive: its commands), Guidance (the classes' path
                      following)        -> setpoints
    pool.send(k)      the workers step from T to T + k
    during the step   MavlinkPart (telemetry at T), the scenario's section
                      participants (swarm, cameras: states at T)
    pool.wait()
    after the step    PoolNotices (what the backend reports: a lost machine
                      replaced), Gathered (rows watched inside the exchange,
                      for the cameras between exchanges), StatusEvents
                      (impacts, divergence, flags), StateLogger
                      (states.parquet), pacing and progress

Every command goes through the run's ``Commander`` (one command path).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from cosim.core.state import STATE_INDEX, VehicleStatus
from cosim.vehicles import get_class

if TYPE_CHECKING:
    from cosim.fdm_pool import Pool
    from cosim.logs import EventLog, StateLog
    from cosim.scenario import Scenario, ScheduleItem
    from cosim.sync.commands import Commander
    from cosim.sync.participants import WatchedStates

log = logging.getLogger(__name__)

_STATUS = STATE_INDEX["status"]
_EVENT_OF_STATUS = {VehicleStatus.GROUND_IMPACT: "ground_impact",
                    VehicleStatus.DIVERGED: "divergence"}


class Schedule:
    """The scenario's schedule: at each item's tick, its ``set:`` values and
    its ``command:`` (through the commander), and a ``schedule`` event."""

    def __init__(self, items: list[ScheduleItem], commander: Commander,
                 events: EventLog) -> None:
        self.pending = list(items)
        self.commander = commander
        self.events = events

    def before_step(self, tick: int, states: np.ndarray, setpoints: np.ndarray) -> None:
        while self.pending and self.pending[0].tick <= tick:
            item = self.pending.pop(0)
            rows = list(item.vehicles)
            self.commander.set_properties(rows, item.sets, setpoints)
            if item.command is not None:
                self.commander.command(rows, item.command, states, setpoints, "schedule")
            self.events.emit("schedule", tick, vehicle=None, vehicles=len(rows),
                             **({"set": dict(item.sets)} if item.sets else {}),
                             **({"command": item.command.source} if item.command else {}))


class MavlinkPart:
    """The run's MAVLink links: what clients sent (before the step: their
    commands through the commander), the telemetry due (during the step), and
    the links' state following commands from elsewhere (the schedule's)."""

    def __init__(self, links: Any, commander: Commander, events: EventLog,
                 ids: list[str]) -> None:
        self.links = links
        self.commander = commander
        self.events = events
        self.ids = ids
        commander.observers.append(self.observe)

    def observe(self, row: int, cmd: Any, source: str) -> None:
        """A command from elsewhere: the vehicle's MAVLink state follows (mode)."""
        if source != "mavlink":
            self.links.local_command(row, cmd)

    def before_step(self, tick: int, states: np.ndarray, setpoints: np.ndarray) -> None:
        for vc in self.links.receive(tick, states):
            self.commander.command([vc.row], vc.command, states, setpoints, "mavlink")
            self.events.emit("mavlink_command", tick, vehicle=self.ids[vc.row],
                             origin=vc.origin, command=vc.command.source)
        for row, kind, fields in self.links.drain_events():
            self.events.emit(kind, tick, vehicle=self.ids[row], **fields)

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        self.links.send_telemetry(tick)


class Guidance:
    """Every class's path following, once per exchange after the commands."""

    def __init__(self, commander: Commander, events: EventLog, ids: list[str]) -> None:
        self.commander = commander
        self.events = events
        self.ids = ids

    def before_step(self, tick: int, states: np.ndarray, setpoints: np.ndarray) -> None:
        for ge in self.commander.update(states, setpoints):
            self.events.emit(ge.kind, tick, vehicle=self.ids[ge.vehicle], **ge.fields)


class PoolNotices:
    """The pool's notices (``Pool.notices``: a lost machine replaced), as events."""

    def __init__(self, pool: Pool, events: EventLog) -> None:
        self.pool = pool
        self.events = events

    def after_step(self, tick: int, states: np.ndarray) -> None:
        while self.pool.notices:
            kind, fields = self.pool.notices.pop(0)
            self.events.emit(kind, tick, **fields)


class Gathered:
    """The rows gathered inside the exchange (``Pool.watch``), copied for the
    participants that asked (``RunContext.watched``) before the next step
    overwrites them."""

    def __init__(self, pool: Pool, watched: WatchedStates) -> None:
        self.pool = pool
        self.watched = watched

    def after_step(self, tick: int, states: np.ndarray) -> None:
        w, m = self.pool.watch, self.pool.watched_count
        assert w is not None
        start = tick - m * w.every
        self.watched.ticks = [start + (c + 1) * w.every for c in range(m)]
        self.watched.states = self.pool.watched[:m].copy()


class StatusEvents:
    """Events from the states: ground impact and divergence (``status``), and
    the flag columns the classes name (``VehicleClass.flag_events``: a stall,
    stall protection)."""

    def __init__(self, scn: Scenario, layout_index: dict[str, int], events: EventLog,
                 ids: list[str]) -> None:
        flags: dict[str, tuple[str, str, str]] = {}
        for name in scn.classes:
            for col, kinds in get_class(name).flag_events.items():
                flags.setdefault(col, kinds)
        self.cols = [layout_index[c] for c in flags]
        self.kinds = tuple(flags.values())
        self.events = events
        self.ids = ids
        self.status = np.zeros(0)
        self.flags = np.zeros((0, 0))

    def start(self, states: np.ndarray) -> None:
        self.status = states[:, _STATUS].copy()
        self.flags = states[:, self.cols].copy()
        self._status_events(0, states, np.zeros_like(self.status))

    def after_step(self, tick: int, states: np.ndarray) -> None:
        new_status = states[:, _STATUS]
        if not np.array_equal(new_status, self.status):
            self._status_events(tick, states, self.status)
            self.status = new_status.copy()
        new_flags = states[:, self.cols]
        if not np.array_equal(new_flags, self.flags):
            for i, j in np.argwhere(new_flags != self.flags).tolist():
                kind, on, off = self.kinds[j]
                self.events.emit(kind, tick, vehicle=self.ids[i],
                                 phase=on if new_flags[i, j] else off)
            self.flags = new_flags.copy()

    def _status_events(self, tick: int, states: np.ndarray, old: np.ndarray) -> None:
        for i in np.flatnonzero(states[:, _STATUS] != old).tolist():
            st = VehicleStatus(int(states[i, _STATUS]))
            if st in _EVENT_OF_STATUS:
                row = states[i]
                self.events.emit(_EVENT_OF_STATUS[st], tick, vehicle=self.ids[i],
                                 lat_deg=row[STATE_INDEX["lat_deg"]],
                                 lon_deg=row[STATE_INDEX["lon_deg"]],
                                 alt_msl_m=row[STATE_INDEX["alt_msl_m"]],
                                 vd_mps=row[STATE_INDEX["vd_mps"]],
                                 airspeed_mps=row[STATE_INDEX["airspeed_mps"]])
                log.warning("tick %d: vehicle %s: %s (frozen)", tick, self.ids[i],
                            _EVENT_OF_STATUS[st])


class StateLogger:
    """``states.parquet``: the states every ``every`` ticks, with each row's
    active command."""

    def __init__(self, states_log: StateLog, every: int, commander: Commander) -> None:
        self.log = states_log
        self.every = every
        self.commander = commander

    def record(self, tick: int, states: np.ndarray) -> None:
        self.log.append(tick, states, self.commander.labels)

    def after_step(self, tick: int, states: np.ndarray) -> None:
        if tick % self.every == 0:
            self.record(tick, states)

    def last(self, tick: int, states: np.ndarray) -> None:
        """The tick the run ends on, if it is not logged yet."""
        if self.log.last_tick != tick:
            self.record(tick, states)


class Clock:
    """Pacing to the wall clock (``--realtime``) and progress."""

    def __init__(self, pacer: Any, progress: Callable[[int, int], None] | None,
                 physics_hz: float, total: int) -> None:
        self.pacer = pacer
        self.progress = progress
        self.hz = physics_hz
        self.total = total

    def after_step(self, tick: int, states: np.ndarray) -> None:
        if self.pacer:
            self.pacer.pace(tick / self.hz)
        if self.progress:
            self.progress(tick, self.total)
