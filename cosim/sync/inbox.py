"""The command inbox: an operator's commands, submitted from other threads
(the live console's web server), applied by the run at its next exchange.

``submit(vehicle_id, spec)`` parses and checks a command of the one
vocabulary (``cosim.guidance.commands``: a schedule item's ``command:``
mapping) at once, against the vehicle's class as the schedule and MAVLink
are checked, and queues it; the inbox, a run participant, applies every
queued command in submission order in its ``before_step`` (after the
schedule's and MAVLink's commands, before guidance) through the run's
``Commander``, emits a ``command`` event and appends one JSON line to the run
folder's ``commands.jsonl`` (flushed at once)::

    {"seq": 0, "tick": 360, "time_s": 3.0, "vehicle": "uav1",
     "command": {"goto": {"north_m": 100, "east_m": 0}}, "source": "operator"}

With ``replay=`` (the lines of such a log) the inbox takes no submissions
and applies each logged command at exactly its tick, so the run is the
logged one again (``cosim.sync.replay``).

Bounded: at most ``MAX_PENDING`` commands wait for an exchange, a spec's
JSON is at most ``MAX_SPEC_BYTES``, a run takes at most ``MAX_COMMANDS``.
Owns ``commands.jsonl``; touches the vehicles only through the commander.
"""

from __future__ import annotations

import itertools
import json
import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import IO, Any

import numpy as np

from cosim.core.limits import MAX_NAME_CHARS
from cosim.core.state import STATE_INDEX
from cosim.errors import ConfigError
from cosim.guidance import DEFAULT_BANK_LIMIT_DEG, Command, parse_command
from cosim.guidance.safety import Limits
from cosim.sync.participants import RunContext
from cosim.vehicles import get_class

log = logging.getLogger(__name__)

#: commands waiting for the next exchange, at most
MAX_PENDING = 64
#: a command's mapping as JSON, at most
MAX_SPEC_BYTES = 4096
#: commands a run takes in all, at most (as many as a replay reads)
MAX_COMMANDS = 100_000
#: the log the inbox writes into the run folder
COMMANDS_LOG = "commands.jsonl"
_AIRSPEED = STATE_INDEX["airspeed_mps"]


@dataclass(frozen=True)
class _Queued:
    seq: int
    row: int
    command: Command
    spec: dict[str, Any]
    tick: int | None = None  # a replayed command's tick


def parse_spec(spec: Any, where: str) -> Command:
    """``spec`` (a command's mapping) as a ``Command``; ``ConfigError`` saying
    what is wrong, prefixed with ``where``."""
    problems: list[str] = []
    cmd = parse_command(spec, ("command",), lambda p, msg: problems.append(
        f"{where}: {'.'.join(map(str, p))}: {msg}"))
    if problems or cmd is None:
        raise ConfigError(problems or [f"{where}: not a command"])
    return cmd


def _plain_spec(spec: Any, where: str) -> dict[str, Any]:
    """A JSON copy of ``spec`` (what the log keeps and the replay parses), at
    most ``MAX_SPEC_BYTES``."""
    if not isinstance(spec, dict):
        raise ConfigError(f"{where}: expected a mapping of commands, got "
                          f"{type(spec).__name__}")
    try:
        text = json.dumps(spec, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: not a JSON mapping: {e}") from None
    if len(text.encode()) > MAX_SPEC_BYTES:
        raise ConfigError(f"{where}: the command is {len(text.encode())} bytes as JSON; "
                          f"at most {MAX_SPEC_BYTES}")
    copy: dict[str, Any] = json.loads(text)
    return copy


class CommandInbox:
    """Commands from outside the run's thread, applied at its exchanges and
    logged (see the module docstring). ``on_applied(entry)`` hears each
    applied command's log entry (in the run's thread; its errors are logged)."""

    name = "command_inbox"

    def __init__(self, source: str = "operator", replay: Sequence[dict[str, Any]] | None = None,
                 on_applied: Callable[[dict[str, Any]], None] | None = None) -> None:
        if not isinstance(source, str) or not 0 < len(source) <= MAX_NAME_CHARS:
            raise ConfigError(f"command inbox: source {source!r}: expected a name of 1 to "
                              f"{MAX_NAME_CHARS} characters")
        self.source = source
        self.on_applied = on_applied
        self.replaying = replay is not None
        self._replay = [dict(e) for e in replay] if replay is not None else []
        self._lock = threading.Lock()
        self._pending: list[_Queued] = []
        self._next_seq = 0
        self._applied = 0
        self._started = False
        self._over = False
        self._ctx: RunContext | None = None
        self._rows: dict[str, int] = {}
        self._airspeed: np.ndarray | None = None  # at the last exchange
        self._file: IO[str] | None = None

    # -- the run's side -------------------------------------------------------------
    def start(self, ctx: RunContext) -> None:
        self._ctx = ctx
        self._rows = {v: i for i, v in enumerate(ctx.ids)}
        queued = sorted((self._replayed(e, ctx) for e in self._replay), key=lambda q: q.seq)
        for a, b in zip(queued, queued[1:]):
            if a.seq == b.seq or (b.tick or 0) < (a.tick or 0):
                raise ConfigError(f"replayed command {b.seq}: at tick {b.tick}, after command "
                                  f"{a.seq} at tick {a.tick}; a log's commands have distinct "
                                  f"numbers in tick order")
        self._file = open(ctx.out_dir / COMMANDS_LOG, "w")  # noqa: SIM115 - closed in finish
        with self._lock:
            self._pending = queued
            self._started = True

    def _replayed(self, e: dict[str, Any], ctx: RunContext) -> _Queued:
        """A logged command, checked to be applicable at its tick in this run."""
        seq, tick, vehicle = e.get("seq"), e.get("tick"), e.get("vehicle")
        where = f"replayed command {seq}"
        if not isinstance(tick, int) or isinstance(tick, bool) or tick < 0 \
                or tick % ctx.control_every:
            raise ConfigError(f"{where}: tick {tick!r} is not an exchange of this run (every "
                              f"{ctx.control_every} ticks)")
        if vehicle not in self._rows:
            raise ConfigError(f"{where}: no vehicle {vehicle!r} in this run")
        spec = _plain_spec(e.get("command"), where)
        if not isinstance(seq, int) or isinstance(seq, bool) or seq < 0:
            raise ConfigError(f"{where}: seq {seq!r} is not a command number (0, 1, ...)")
        return _Queued(seq, self._rows[vehicle], parse_spec(spec, where), spec, tick)

    def before_step(self, tick: int, states: np.ndarray, setpoints: np.ndarray) -> None:
        with self._lock:
            self._airspeed = states[:, _AIRSPEED].copy()
            due = self._pending
            if self.replaying:  # in tick order: those due now lead
                due = list(itertools.takewhile(lambda q: (q.tick or 0) <= tick, due))
            if not due:
                return
            self._pending = self._pending[len(due):]
        ctx = self._ctx
        assert ctx is not None and self._file is not None
        for q in due:
            if q.tick is not None and q.tick != tick:
                raise ConfigError(f"replayed command {q.seq}: logged at tick {q.tick}, "
                                  f"reached at {tick}: the log is not in tick order")
            vehicle = ctx.ids[q.row]
            entry = {"seq": q.seq, "tick": tick, "time_s": tick / ctx.physics_hz,
                     "vehicle": vehicle, "command": q.spec, "source": self.source}
            # logged before it acts: every command that moved a vehicle is in the log
            self._file.write(json.dumps(entry) + "\n")
            self._file.flush()
            ctx.commander.command([q.row], q.command, states, setpoints, self.source)
            ctx.events.emit("command", tick, vehicle=vehicle, source=self.source,
                            label=q.command.label(), seq=q.seq)
            self._applied += 1
            if self.on_applied is not None:
                try:
                    self.on_applied(entry)
                except Exception:
                    log.exception("command %d: on_applied failed", q.seq)

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        pass

    def finish(self, tick: int, reason: str) -> dict[str, Any]:
        with self._lock:
            self._over = True
            left = len(self._pending)
            self._pending = []
        if self._file is not None:
            self._file.close()
        if left:
            log.warning("%d command(s) submitted or logged were not applied: the run ended "
                        "(%s) at tick %d", left, reason, tick)
        return {"commands": self._applied}

    def after_run(self, out_dir: Any) -> None:
        pass

    # -- the submitters' side ---------------------------------------------------------
    def submit(self, vehicle_id: str, spec: dict[str, Any]) -> int:
        """Queue ``spec`` (a command's mapping) for vehicle ``vehicle_id`` at the
        next exchange; its sequence number. ``ConfigError`` naming the problem:
        a bad command, an unknown vehicle, one whose class takes no commands, a
        command its class refuses, a full queue, a run not started or over, or
        one that has taken ``MAX_COMMANDS``."""
        where = f"command for {vehicle_id!r}"
        plain = _plain_spec(spec, where)
        cmd = parse_spec(plain, where)
        with self._lock:
            if self.replaying:
                raise ConfigError(f"{where}: this inbox replays a logged run; it takes no "
                                  f"commands")
            if self._over:
                raise ConfigError(f"{where}: the run is over")
            if not self._started or self._ctx is None:
                raise ConfigError(f"{where}: the run has not started yet (its vehicles are "
                                  f"being built); try again in a moment")
            row = self._rows.get(vehicle_id) if isinstance(vehicle_id, str) else None
            if row is None:
                known = list(self._rows)
                raise ConfigError(f"{where}: no such vehicle; the run's are "
                                  f"{', '.join(known[:5])}"
                                  f"{f' and {len(known) - 5} more' if len(known) > 5 else ''}")
            self._check(cmd, row, where)
            if self._next_seq >= MAX_COMMANDS:
                raise ConfigError(f"{where}: the run has taken {MAX_COMMANDS} commands, as "
                                  f"many as a replay of it can read; it takes no more")
            if len(self._pending) >= MAX_PENDING:
                raise ConfigError(f"{where}: {MAX_PENDING} commands already wait for the "
                                  f"next exchange; try again in a moment")
            seq = self._next_seq
            self._next_seq += 1
            self._pending.append(_Queued(seq, row, cmd, plain))
        return seq

    def _check(self, cmd: Command, row: int, where: str) -> None:
        """The vehicle's class takes ``cmd`` as it would from the schedule (the
        rule of every command path); gimbal angles and stills are for the
        cameras, as there."""
        if not cmd.flies:
            return
        assert self._ctx is not None
        spec = self._ctx.scenario.vehicles[row]
        vc = get_class(spec.vehicle_class)
        if not vc.commandable:
            raise ConfigError(f"{where}: model {spec.model} (class {spec.vehicle_class}) "
                              f"takes no commands")
        speed = float(self._airspeed[row]) if self._airspeed is not None else spec.airspeed_mps
        lim = Limits(spec.terrain_alt_m, vc.min_alt_agl_m(spec.profile),
                     speed if np.isfinite(speed) else spec.airspeed_mps, DEFAULT_BANK_LIMIT_DEG)
        problems = vc.command_problems(cmd, spec, lim)
        if problems:
            raise ConfigError([f"{where}: {p}" for p in problems])
