"""The lockstep tick loop: one scenario from start to a clean stop.

Time is an integer physics ``tick``; seconds are derived. Every exchange
advances every vehicle by the same ``control_every`` ticks, so all vehicles
are at the same simulation time whenever anything (schedule, logging,
later controllers and renderers) looks at them. The loop stops cleanly on
completion, on ``stop()`` (Ctrl-C/SIGTERM in the CLI) and on errors, and
always closes the logs and writes ``summary.json`` first. A run starts from
empty outputs (a previous run's files in its folder are removed), logs the
tick it ends on, and reports schedule items that a shortened duration
leaves out as ``schedule_skipped`` events.
"""

from __future__ import annotations

import faulthandler
import logging
import os
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cosim.core.state import STATE_FIELDS
from cosim.errors import VehicleError, WorkerDied, WorkerError
from cosim.fdm_pool import make_pool
from cosim.fdm_pool.base import Pool, Watch
from cosim.logs import DiskReserve, EventLog, StateLog, clear_outputs, write_json_atomic
from cosim.scenario import Scenario
from cosim.sync import parts
from cosim.sync.commands import Commander
from cosim.sync.pacing import Pacer
from cosim.sync.participants import (
    Participant,
    ParticipantFailed,
    RunContext,
    WatchedStates,
    build_participants,
    needs_mavlink,
    watch_for,
)
from cosim.sync.parts import StateLogger, StatusEvents
from cosim.vehicles.registry import get_class, state_layout

log = logging.getLogger(__name__)

ProgressFn = Callable[[int, int], None]
#: disk kept free during a run (``DiskReserve``) for closing its files on a full
#: disk, and separately for the final summary.json
RESERVE_BYTES = 8 * 1024 * 1024
SUMMARY_RESERVE_BYTES = 1024 * 1024


#: libyaml's emitter where PyYAML has it (a 100,000-vehicle scenario resolves in
#: a second rather than half a minute), else PyYAML's own
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


@dataclass
class RunResult:
    out_dir: Path
    stop_reason: str
    ticks: int
    summary: dict[str, Any] = field(default_factory=dict)
    error: BaseException | None = None

    @property
    def ok(self) -> bool:
        return self.stop_reason == "completed"


@dataclass
class _Outcome:
    """How far a run got and how it ended, filled in as it goes."""
    wall0: float
    tick: int = 0
    reason: str = "error"
    error: BaseException | None = None
    startup_s: float = 0.0
    loop0: float | None = None  # when the tick loop started
    loop_s: float = 0.0
    #: seconds the loop was held by ``Run.pause`` (not in ``wall_time_s``)
    paused_s: float = 0.0
    workers: int = 1
    complete: bool = True  # every output written and closed
    sections: dict[str, Any] = field(default_factory=dict)  # participants' summary parts
    summary: dict[str, Any] = field(default_factory=dict)
    #: seconds of the tick loop spent in each part (``Timed``)
    split: dict[str, float] = field(default_factory=dict)


class Timed:
    """A participant's step (or the pool's wait) that adds the time it takes
    to ``split[name]``: where a run's time goes, in ``summary.json``."""

    __slots__ = ("fn", "name", "split")

    def __init__(self, fn: Callable[..., Any], split: dict[str, float],
                 name: str | None = None) -> None:
        self.fn = fn
        self.split = split
        owner = getattr(fn, "__self__", None)
        self.name: str = name or (f"{type(owner).__name__}.{fn.__name__}" if owner is not None
                                  else str(getattr(fn, "__qualname__", repr(fn))))
        split.setdefault(self.name, 0.0)

    def __call__(self, *args: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return self.fn(*args)
        finally:
            self.split[self.name] += time.perf_counter() - t0


class Run:
    """One run of a scenario into an output folder."""

    def __init__(self, scenario: Scenario, out_dir: str | Path, backend: str = "process",
                 workers: int | None = None, realtime: float | None = None,
                 progress: ProgressFn | None = None, step_timeout_s: float = 60.0,
                 mavlink: Any = None, external_controller: bool = False,
                 extra_participants: Sequence[Any] = (),
                 backend_options: dict[str, Any] | None = None) -> None:
        self.scn = scenario
        #: participants the caller adds (the live view), after the scenario's
        self.extra_participants = list(extra_participants)
        self.out = Path(out_dir)
        self.backend = backend
        self.workers = workers
        #: the backend's own options (``Backend.options``: a cluster's address)
        self.backend_options = dict(backend_options or {})
        self.pacer = Pacer(realtime) if realtime else None
        self.progress = progress
        self.step_timeout_s = step_timeout_s  # a worker silent this long is a failure
        #: a cosim.mavlink.MavlinkConfig: every vehicle on one MAVLink link
        if mavlink is None and (scenario.mavlink is not None or needs_mavlink(scenario)):
            from cosim.mavlink import MavlinkConfig

            # the scenario's link, else in-process only (no socket) for its controller
            mavlink = MavlinkConfig.of_scenario(
                scenario.mavlink, [v.id for v in scenario.vehicles]) or MavlinkConfig(url=None)
        self.mavlink_config = mavlink
        #: the scenario's controller runs in another process (``cosim swarm
        #: --connect``), kept in lockstep over ``mavlink`` (lockstep_sysid set)
        self.external_controller = external_controller
        self.mavlink: Any = None
        self._stop = threading.Event()
        self._stop_reason = "interrupted"
        self._go = threading.Event()  # cleared while paused (``pause``)
        self._go.set()
        self._building = False
        self.pool: Pool | None = None
        self.participants: list[Participant] = []

    def stop(self, reason: str = "interrupted") -> None:
        """Ask the loop to stop after the current tick (safe from a signal handler)."""
        self._stop_reason = reason
        self._stop.set()

    def pause(self) -> None:
        """Hold the loop before its next exchange until ``resume`` (safe from
        any thread): simulated time stops and nothing is skipped, so the run's
        states are those of a run never paused. The pacer's clock stops too
        (no lateness, no catching up afterwards); ``stop`` still ends it."""
        self._go.clear()

    def resume(self) -> None:
        """Let a paused loop go on (nothing if it is not paused)."""
        self._go.set()

    @property
    def paused(self) -> bool:
        return not self._go.is_set()

    @property
    def building(self) -> bool:
        """True while the vehicles are being built and trimmed. A stop request
        then only takes effect once the build is over; a caller that wants it
        at once (the CLI's signal handler) raises ``KeyboardInterrupt`` in the
        main thread instead: the pool cleans up, and the run ends with the
        reason given to ``stop`` and writes its summary as usual."""
        return self._building

    def run(self) -> RunResult:
        """Build, fly, finish: the run's outputs are complete and closed, and
        ``summary.json`` written, however the run ends."""
        scn, out = self.scn, self.out
        out.mkdir(parents=True, exist_ok=True)
        clear_outputs(out)  # a new run never mixes with an old one's files
        (out / "scenario.resolved.yaml").write_text(
            yaml.dump(scn.resolved_dict(), Dumper=_DUMPER, sort_keys=False))
        ids = [v.id for v in scn.vehicles]
        hz = scn.rates.physics_hz
        events = EventLog(out / "events.jsonl", hz)
        layout = state_layout(scn.vehicles)
        states_log = StateLog(out / "states.parquet", ids, scn.origin.frame, hz,
                              extra=[(f.name, j) for j, f in enumerate(layout)
                                     if j >= len(STATE_FIELDS)])
        # items a shortened duration (with_duration, --duration-s) leaves out
        skipped = [item for item in scn.schedule if item.tick >= scn.total_ticks]
        for item in skipped:
            log.warning("schedule[%d] at %g s is at or after the end of the run (%g s): "
                        "skipped", item.index, item.at_s, scn.total_ticks / hz)
        o = _Outcome(wall0=time.perf_counter())
        events.emit("run_start", 0, scenario=scn.name, vehicles=len(ids), backend=self.backend)
        # a summary from the start (replaced at the end), and room kept for the
        # last writes: a full disk still leaves a readable summary.json
        write_json_atomic(out / "summary.json", {
            **self._summary("running", 0, 0.0, 0.0, 1, {}, 0, None), "complete": False})
        reserve = DiskReserve(out / ".cosim-reserve", RESERVE_BYTES)
        summary_reserve = DiskReserve(out / ".cosim-reserve-summary", SUMMARY_RESERVE_BYTES)
        # a hard crash of this process (segfault, abort) leaves its Python traceback here
        fault_file = open(out / "faulthandler.log", "w")  # noqa: SIM115 - closed below
        fault_was_enabled = faulthandler.is_enabled()
        faulthandler.enable(fault_file, all_threads=True)
        try:
            self._fly(o, events, states_log)
        except KeyboardInterrupt:  # a stop, not an error
            o.reason = self._stop_reason if self._stop.is_set() else "interrupted"
            if self.pool is None and self._building:
                log.warning("stopped while building the vehicles (%s)", o.reason)
        except Exception as e:
            self._failed(o, e, events)
        finally:
            self._building = False
            reserve.release()  # room to close videos, logs and tlogs on a full disk
            if self.mavlink is not None:
                self.mavlink.close()
            if o.loop0 is not None and o.loop_s == 0.0:
                o.loop_s = time.perf_counter() - o.loop0
            try:
                self._finish_participants(o, events)
                self._close_logs(o, events, states_log, skipped)
                summary_reserve.release()
                self._write_summary(o, events, states_log)
            finally:
                reserve.release()
                summary_reserve.release()
                self._end_fault_log(fault_file, fault_was_enabled)
        self._after_run(states_log.rows_logged)
        return RunResult(out, o.reason, o.tick, o.summary, o.error)

    def _fly(self, o: _Outcome, events: EventLog, states_log: StateLog) -> None:
        """Build the pool and the participants, then step to the end or a stop."""
        scn = self.scn
        log.info("building and trimming %d vehicles (%s backend)", len(scn.vehicles),
                 self.backend)
        self._building = True
        if self._stop.is_set():
            raise KeyboardInterrupt
        # the participants are made first (some ask for rows gathered inside
        # exchanges), but are the run's (finished at its end) only once the pool is
        wanted = build_participants(
            scn, external_controller=self.external_controller) + self.extra_participants
        options = dict(self.backend_options)
        watch = watch_for(wanted, scn.rates.control_every)
        if watch is not None:
            options["watch"] = Watch(watch[0], watch[1], scn.rates.control_every)
        pool = make_pool(scn.vehicles, scn.rates.dt_s, scn.channels, self.backend, self.workers,
                         **options)
        with pool:  # closed however the rest of the set-up ends
            self._building = False
            self.pool = pool
            o.workers = pool.workers
            o.startup_s = time.perf_counter() - o.wall0
            log.info("%d vehicles ready in %.2f s on %d worker(s)", len(scn.vehicles),
                     o.startup_s, o.workers)
            ids = [v.id for v in scn.vehicles]
            before, during, after, logger, status_events = self._parts(
                pool, events, states_log, ids, scn.total_ticks, wanted)
            states = pool.states
            status_events.start(states)
            logger.record(0, states)
            o.loop0 = time.perf_counter()
            if self.pacer:
                self.pacer.start()
            before, during, after = ([Timed(f, o.split) for f in fs]
                                     for fs in (before, during, after))
            states = self._loop(o, pool, states, before, during, after)
            logger.last(o.tick, states)
            o.loop_s = time.perf_counter() - o.loop0

    def _loop(self, o: _Outcome, pool: Pool, states: np.ndarray, before: list[Any],
              during: list[Any], after: list[Any]) -> np.ndarray:
        """The lockstep tick loop: every participant's step, once per exchange."""
        k, total = self.scn.rates.control_every, self.scn.total_ticks
        copy_states = bool(self.participants)  # they keep the states at ``tick``
        wait = Timed(pool.wait, o.split, "pool: stepping (waiting for the workers)")
        while o.tick < total:
            if self._stop.is_set():
                o.reason = self._stop_reason
                return states
            if not self._go.is_set():
                self._hold(o)
                continue  # a stop while held ends the run here
            for step in before:  # schedule, MAVLink, participants' commands, guidance
                step(o.tick, states, pool.setpoints)
            at_tick = states.copy() if copy_states else states  # the step overwrites
            pool.send(k)
            for work in during:  # telemetry, controllers, cameras: while it steps
                work(o.tick, at_tick)
            states = wait(self.step_timeout_s)
            o.tick += k
            for record in after:  # events, logs, pacing, progress
                record(o.tick, states)
        o.reason = "completed"
        return states

    def _hold(self, o: _Outcome) -> None:
        """Wait while paused (or until a stop), the pacer's clock stopped."""
        t0 = time.perf_counter()
        if self.pacer:
            self.pacer.hold()
        while not self._go.wait(0.05) and not self._stop.is_set():
            pass
        if self.pacer:
            self.pacer.release()
        o.paused_s += time.perf_counter() - t0

    @staticmethod
    def _failed(o: _Outcome, e: Exception, events: EventLog) -> None:
        """An exception that ended the loop, as the run's reason and an event."""
        o.error = e
        o.reason = "worker_failure" if isinstance(e, WorkerDied) else "error"
        if isinstance(e, WorkerDied):
            events.emit("worker_failure", o.tick, vehicle=None, worker=e.worker, pid=e.pid,
                        exitcode=e.exitcode, vehicles=e.vehicles, message=str(e))
        elif isinstance(e, WorkerError):
            events.emit("error", o.tick, vehicle=e.vehicle, worker=e.worker, message=str(e))
        elif isinstance(e, VehicleError):
            events.emit("error", o.tick, vehicle=e.vehicle, message=str(e))
        else:
            events.emit("error", o.tick, vehicle=getattr(e, "vehicle", None),
                        message=f"{type(e).__name__}: {e}")

    def _finish_participants(self, o: _Outcome, events: EventLog) -> None:
        """Participants finish their work (a render queue drains) inside the
        run's wall time, and may still emit events; each one's summary section
        is kept, and one part's failure fails the run without losing the rest."""
        t_fin = time.perf_counter()
        for part in self.participants:
            failure: BaseException | None = None
            try:
                section = part.finish(o.tick, o.reason)
            except ParticipantFailed as e:  # its section is still the summary's
                section, failure = e.section, e.error
            except Exception as e:
                log.exception("%s: finishing failed", part.name)
                section, failure = {"error": f"{type(e).__name__}: {e}"}, e
            if section is not None:
                o.sections[part.name] = section
                if "error" in section:  # its outputs stopped short
                    o.complete = False
            if failure is not None:  # a failed part fails the run, said once
                o.complete = False
                log.error("%s: %s", part.name, failure)
                if o.reason == "completed":
                    o.reason = "error"
                o.error = o.error if o.error is not None else failure
                events.emit("error", o.tick, vehicle=getattr(failure, "vehicle", None),
                            message=f"{type(failure).__name__}: {failure}")
        if o.loop0 is not None:
            o.loop_s += time.perf_counter() - t_fin

    def _close_logs(self, o: _Outcome, events: EventLog, states_log: StateLog,
                    skipped: list[Any]) -> None:
        try:
            states_log.close()
        except Exception as e:  # the ticks stay journalled; read_states reads them
            log.error("could not write states.parquet: %s", e)
            if o.reason != "worker_failure":
                o.reason = "error"
            o.error = o.error if o.error is not None else e
            events.emit("error", o.tick, vehicle=None,
                        message=f"writing states.parquet failed: {type(e).__name__}: {e}")
        total_s = self.scn.total_ticks / self.scn.rates.physics_hz
        for item in skipped:
            events.emit("schedule_skipped", o.tick, vehicle=None, index=item.index,
                        at_s=item.at_s, vehicles=len(item.vehicles),
                        reason=f"at or after the end of the run ({total_s:g} s)")
        events.emit("stop", o.tick, reason=o.reason)
        events.close()

    def _write_summary(self, o: _Outcome, events: EventLog, states_log: StateLog) -> None:
        summary = self._summary(o.reason, o.tick, o.startup_s, o.loop_s - o.paused_s,
                                o.workers, events.counts, states_log.rows_logged, o.error)
        if o.paused_s:
            summary["paused_s"] = round(o.paused_s, 4)
        if self.mavlink is not None:
            summary["mavlink"] = {"url": self.mavlink_config.url,
                                  "counters": self.mavlink.counters()}
        summary.update(o.sections)
        if o.split:
            summary["time_split_s"] = {k: round(v, 4) for k, v in
                                       sorted(o.split.items(), key=lambda kv: -kv[1])}
        if events.dropped:
            summary["events_dropped"] = events.dropped
        summary["complete"] = o.complete and states_log.complete and events.complete
        o.summary = summary
        try:
            write_json_atomic(self.out / "summary.json", summary)
        except OSError as e:  # the summary written at the start stays, incomplete
            log.error("could not write the final summary.json: %s", e)
            o.error = o.error if o.error is not None else e
            if o.reason == "completed":
                o.reason = "error"

    def _after_run(self, rows_logged: int) -> None:
        """Plots and other after-the-fact outputs; never able to lose the run."""
        for part in self.participants:
            try:
                part.after_run(self.out)
            except Exception as e:
                log.warning("%s: %s", part.name, e)
        if self.scn.plot and rows_logged:
            try:
                from cosim.logs.plot import plot_run

                log.info("plot: %s", plot_run(self.out))
            except Exception as e:
                log.warning("could not write track.png: %s", e)

    def _parts(self, pool: Pool, events: EventLog, states_log: StateLog, ids: list[str],
               total: int, wanted: list[Any]) -> tuple[list[Any], list[Any], list[Any],
                                                       StateLogger, StatusEvents]:
        """The run's participants, started: the steps the loop calls before,
        during and after each pool step (``cosim.sync.parts``)."""
        scn = self.scn
        hz = scn.rates.physics_hz
        start_ned = np.stack(scn.origin.frame.geodetic_to_ned(
            [v.lat_deg for v in scn.vehicles], [v.lon_deg for v in scn.vehicles],
            [v.alt_msl_m for v in scn.vehicles]), axis=1)
        commander = Commander(scn, scn.origin.frame, start_ned[:, :2].copy(),
                              {c: i for i, c in enumerate(pool.channels)})
        before: list[Any] = [parts.Schedule([i for i in scn.schedule if i.tick < total],
                                            commander, events).before_step]
        during: list[Any] = []
        if self.mavlink_config is not None:
            from cosim.mavlink import MavlinkLinks

            # each vehicle's class hands mavlink its personality and safety rule
            self.mavlink = MavlinkLinks(scn.vehicles, get_class, hz, self.mavlink_config,
                                        tlog_dir=self.out)
            for url, specs, (host, port) in zip(self.mavlink.urls, self.mavlink.specs,
                                                 self.mavlink.local_addresses):
                if url is not None:
                    log.info("MAVLink: vehicles %s..%s (system ids 1..%d) on %s (local %s:%d)",
                             ids[specs[0].row], ids[specs[-1].row], len(specs), url, host,
                             port)
            mav_part = parts.MavlinkPart(self.mavlink, commander, events, ids)
            before.append(mav_part.before_step)
            during.append(mav_part.on_exchange)
        self.participants = wanted
        watched = (WatchedStates(pool.watch.rows, [], pool.watched[:0].copy())
                   if pool.watch is not None else None)
        ctx = RunContext(scn, self.out, ids, scn.origin.frame, start_ned, hz,
                         scn.rates.control_every, events, self.mavlink, pool.workers,
                         commander, frame_taps=[], watched=watched,
                         columns=tuple(f.name for f in pool.layout),
                         step_timeout_s=self.step_timeout_s)
        for part in self.participants:  # taps on the frames, before the cameras start
            pre = getattr(part, "prepare", None)
            if pre is not None:
                pre(ctx)
        for part in self.participants:
            part.start(ctx)
            during.append(part.on_exchange)
            hook = getattr(part, "before_step", None)
            if hook is not None:  # commands of its own (an operator's), in participant order
                before.append(hook)
        if commander.active:  # guidance last: it follows every command of the exchange
            before.append(parts.Guidance(commander, events, ids).before_step)
        index = {f.name: j for j, f in enumerate(pool.layout)}
        status_events = parts.StatusEvents(scn, index, events, ids)
        logger = parts.StateLogger(states_log, scn.rates.log_every, commander)
        after = [parts.PoolNotices(pool, events).after_step, status_events.after_step,
                 logger.after_step,
                 *([parts.Gathered(pool, watched).after_step] if watched is not None else []),
                 parts.Clock(self.pacer, self.progress, hz, total).after_step]
        return before, during, after, logger, status_events

    @staticmethod
    def _end_fault_log(f: Any, was_enabled: bool) -> None:
        """Stop writing faulthandler.log (removed if empty); restore faulthandler
        as it was (as pytest and ``python -X faulthandler`` have it: to stderr)."""
        faulthandler.disable()
        if was_enabled:
            faulthandler.enable(sys.__stderr__ or sys.stderr, all_threads=True)
        f.close()
        try:
            if os.path.getsize(f.name) == 0:
                os.unlink(f.name)
        except OSError:
            pass

    def _summary(self, reason: str, tick: int, startup_s: float, loop_s: float, workers: int,
                 counts: dict[str, int], rows: int, error: BaseException | None
                 ) -> dict[str, Any]:
        scn = self.scn
        sim_s = tick / scn.rates.physics_hz
        s: dict[str, Any] = {
            "scenario": scn.name,
            "scenario_path": scn.path,
            "vehicles": len(scn.vehicles),
            "backend": self.backend,
            "workers": workers,
            "physics_hz": scn.rates.physics_hz,
            "control_hz": scn.rates.control_hz,
            "log_hz": scn.rates.log_hz,
            "seed": scn.seed,
            "ticks": tick,
            "sim_time_s": sim_s,
            "startup_s": round(startup_s, 4),
            "wall_time_s": round(loop_s, 4),
            "real_time_factor": round(sim_s / loop_s, 4) if loop_s > 0 else None,
            "stop_reason": reason,
            "events": counts,
            "state_rows": rows,
            "outputs": {"states": "states.parquet", "events": "events.jsonl",
                        "scenario": "scenario.resolved.yaml"},
        }
        if self.pacer:
            s["realtime"] = self.pacer.stats()
        if error is not None:
            s["error"] = f"{type(error).__name__}: {error}"
        return s


def run_scenario(scenario: Scenario, out_dir: str | Path, **kw: Any) -> RunResult:
    return Run(scenario, out_dir, **kw).run()
