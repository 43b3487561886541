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
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cosim.errors import VehicleError, WorkerDied, WorkerError
from cosim.fdm_pool import make_pool
from cosim.fdm_pool.base import Pool
from cosim.logs import DiskReserve, EventLog, StateLog, clear_outputs, write_json_atomic
from cosim.scenario import Scenario
from cosim.sync import parts
from cosim.sync.commands import Commander
from cosim.sync.pacing import Pacer
from cosim.sync.participants import (
    Participant,
    ParticipantFailed,
    RunContext,
    build_participants,
    needs_mavlink,
)
from cosim.sync.parts import StateLogger, StatusEvents
from cosim.vehicles.spec import STATE_FIELDS, state_layout

log = logging.getLogger(__name__)

ProgressFn = Callable[[int, int], None]
#: disk kept free during a run (``DiskReserve``) for closing its files on a full
#: disk, and separately for the final summary.json
RESERVE_BYTES = 8 * 1024 * 1024
SUMMARY_RESERVE_BYTES = 1024 * 1024


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


class Run:
    """One run of a scenario into an output folder."""

    def __init__(self, scenario: Scenario, out_dir: str | Path, backend: str = "process",
                 workers: int | None = None, realtime: float | None = None,
                 progress: ProgressFn | None = None, step_timeout_s: float = 60.0,
                 mavlink: Any = None, external_controller: bool = False) -> None:
        self.scn = scenario
        self.out = Path(out_dir)
        self.backend = backend
        self.workers = workers
        self.pacer = Pacer(realtime) if realtime else None
        self.progress = progress
        self.step_timeout_s = step_timeout_s  # a worker silent this long is a failure
        #: a cosim.mavlink.MavlinkConfig: every vehicle on one MAVLink link
        if mavlink is None and (scenario.mavlink is not None or needs_mavlink(scenario)):
            from cosim.mavlink import MavlinkConfig

            # the scenario's link, else in-process only (no socket) for its controller
            mavlink = MavlinkConfig.of_scenario(scenario.mavlink) or MavlinkConfig(url=None)
        self.mavlink_config = mavlink
        #: the scenario's controller runs in another process (``cosim swarm
        #: --connect``), kept in lockstep over ``mavlink`` (lockstep_sysid set)
        self.external_controller = external_controller
        self.mavlink: Any = None
        self._stop = threading.Event()
        self._stop_reason = "interrupted"
        self._building = False
        self.pool: Pool | None = None
        self.participants: list[Participant] = []

    def stop(self, reason: str = "interrupted") -> None:
        """Ask the loop to stop after the current tick (safe from a signal handler)."""
        self._stop_reason = reason
        self._stop.set()

    @property
    def building(self) -> bool:
        """True while the vehicles are being built and trimmed. A stop request
        then only takes effect once the build is over; a caller that wants it
        at once (the CLI's signal handler) raises ``KeyboardInterrupt`` in the
        main thread instead: the pool cleans up, and the run ends with the
        reason given to ``stop`` and writes its summary as usual."""
        return self._building

    def run(self) -> RunResult:
        scn, out = self.scn, self.out
        out.mkdir(parents=True, exist_ok=True)
        clear_outputs(out)  # a new run never mixes with an old one's files
        (out / "scenario.resolved.yaml").write_text(
            yaml.safe_dump(scn.resolved_dict(), sort_keys=False))
        ids = [v.id for v in scn.vehicles]
        hz = scn.rates.physics_hz
        events = EventLog(out / "events.jsonl", hz)
        layout = state_layout(scn.vehicles)
        states_log = StateLog(out / "states.parquet", ids, scn.origin.frame, hz,
                              extra=[(f.name, j) for j, f in enumerate(layout)
                                     if j >= len(STATE_FIELDS)])
        k, total = scn.rates.control_every, scn.total_ticks
        # items a shortened duration (with_duration, --duration-s) leaves out
        skipped = [item for item in scn.schedule if item.tick >= total]
        for item in skipped:
            log.warning("schedule[%d] at %g s is at or after the end of the run (%g s): "
                        "skipped", item.index, item.at_s, total / hz)
        tick = 0
        reason = "error"
        error: BaseException | None = None
        wall0 = time.perf_counter()
        startup_s = loop_s = 0.0
        loop0: float | None = None
        workers_used = 1
        events.emit("run_start", 0, scenario=scn.name, vehicles=len(ids), backend=self.backend)
        # a summary from the start (replaced at the end), and room kept for the
        # last writes: a full disk still leaves a readable summary.json
        write_json_atomic(out / "summary.json", {
            **self._summary("running", 0, 0.0, 0.0, 1, {}, 0, None), "complete": False})
        reserve = DiskReserve(out / ".cosim-reserve", RESERVE_BYTES)
        summary_reserve = DiskReserve(out / ".cosim-reserve-summary", SUMMARY_RESERVE_BYTES)
        complete = True  # every output written and closed
        # a hard crash of this process (segfault, abort) leaves its Python traceback here
        fault_path = out / "faulthandler.log"
        fault_file = open(fault_path, "w")  # noqa: SIM115 - closed in the finally below
        fault_was_enabled = faulthandler.is_enabled()
        faulthandler.enable(fault_file, all_threads=True)
        try:
            log.info("building and trimming %d vehicles (%s backend)", len(ids), self.backend)
            self._building = True
            if self._stop.is_set():
                raise KeyboardInterrupt
            pool = make_pool(scn.vehicles, scn.rates.dt_s, scn.channels, self.backend,
                             self.workers)
            with pool:  # closed however the rest of the set-up ends
                self._building = False
                self.pool = pool
                workers_used = pool.workers
                startup_s = time.perf_counter() - wall0
                log.info("%d vehicles ready in %.2f s on %d worker(s)", len(ids), startup_s,
                         workers_used)
                before, during, after, logger, status_events = self._parts(
                    pool, events, states_log, ids, total)
                states = pool.states
                status_events.start(states)
                logger.record(0, states)
                copy_states = bool(self.participants)  # they keep the states at ``tick``
                loop0 = time.perf_counter()
                if self.pacer:
                    self.pacer.start()
                while tick < total:
                    if self._stop.is_set():
                        reason = self._stop_reason
                        break
                    for step in before:  # commands, then guidance: setpoints
                        step(tick, states, pool.setpoints)
                    at_tick = states.copy() if copy_states else states  # the step overwrites
                    pool.send(k)
                    for work in during:  # telemetry, controllers, cameras: while it steps
                        work(tick, at_tick)
                    states = pool.wait(self.step_timeout_s)
                    tick += k
                    for record in after:  # events, logs, pacing, progress
                        record(tick, states)
                else:
                    reason = "completed"
                logger.last(tick, states)
                loop_s = time.perf_counter() - loop0
        except WorkerDied as e:
            reason, error = "worker_failure", e
            events.emit("worker_failure", tick, vehicle=None, worker=e.worker, pid=e.pid,
                        exitcode=e.exitcode, vehicles=e.vehicles, message=str(e))
        except WorkerError as e:
            reason, error = "error", e
            events.emit("error", tick, vehicle=e.vehicle, worker=e.worker, message=str(e))
        except VehicleError as e:
            reason, error = "error", e
            events.emit("error", tick, vehicle=e.vehicle, message=str(e))
        except Exception as e:
            reason, error = "error", e
            events.emit("error", tick, vehicle=getattr(e, "vehicle", None),
                        message=f"{type(e).__name__}: {e}")
        except KeyboardInterrupt:  # a stop, not an error
            reason = self._stop_reason if self._stop.is_set() else "interrupted"
            if self.pool is None and self._building:
                log.warning("stopped while building the vehicles (%s)", reason)
        finally:
            self._building = False
            reserve.release()  # room to close videos, logs and tlogs on a full disk
            if self.mavlink is not None:
                self.mavlink.close()
            if loop0 is not None and loop_s == 0.0:
                loop_s = time.perf_counter() - loop0
            try:
                # participants finish their work (a render queue drains) inside
                # the run's wall time, and may still emit events
                t_fin = time.perf_counter()
                sections: dict[str, Any] = {}
                for part in self.participants:
                    failure: BaseException | None = None
                    try:
                        section = part.finish(tick, reason)
                    except ParticipantFailed as e:  # its section is still the summary's
                        section, failure = e.section, e.error
                    except Exception as e:  # one part's failure must not lose the summary
                        log.exception("%s: finishing failed", part.name)
                        section, failure = {"error": f"{type(e).__name__}: {e}"}, e
                    if section is not None:
                        sections[part.name] = section
                        if "error" in section:  # its outputs stopped short
                            complete = False
                    if failure is not None:  # a failed part fails the run, said once
                        complete = False
                        log.error("%s: %s", part.name, failure)
                        if reason == "completed":
                            reason = "error"
                        error = error if error is not None else failure
                        events.emit("error", tick, vehicle=getattr(failure, "vehicle", None),
                                    message=f"{type(failure).__name__}: {failure}")
                if loop0 is not None:
                    loop_s += time.perf_counter() - t_fin
                try:
                    states_log.close()
                except Exception as e:  # the ticks stay journalled; read_states reads them
                    log.error("could not write states.parquet: %s", e)
                    if reason != "worker_failure":
                        reason = "error"
                    error = error if error is not None else e
                    events.emit("error", tick, vehicle=None,
                                message=f"writing states.parquet failed: {type(e).__name__}: {e}")
                for item in skipped:
                    events.emit("schedule_skipped", tick, vehicle=None, index=item.index,
                                at_s=item.at_s, vehicles=len(item.vehicles),
                                reason=f"at or after the end of the run ({total / hz:g} s)")
                events.emit("stop", tick, reason=reason)
                events.close()
                summary = self._summary(reason, tick, startup_s, loop_s, workers_used,
                                        events.counts, states_log.rows_logged, error)
                if self.mavlink is not None:
                    summary["mavlink"] = {"url": self.mavlink_config.url,
                                          "counters": self.mavlink.counters()}
                summary.update(sections)
                if events.dropped:
                    summary["events_dropped"] = events.dropped
                summary["complete"] = complete and states_log.complete and events.complete
                summary_reserve.release()
                try:
                    write_json_atomic(out / "summary.json", summary)
                except OSError as e:  # the summary written at the start stays, incomplete
                    log.error("could not write the final summary.json: %s", e)
                    error = error if error is not None else e
                    if reason == "completed":
                        reason = "error"
            finally:
                reserve.release()
                summary_reserve.release()
                self._end_fault_log(fault_file, fault_was_enabled)
        for part in self.participants:
            try:
                part.after_run(out)
            except Exception as e:  # a plot must never lose a finished run
                log.warning("%s: %s", part.name, e)
        if scn.plot and states_log.rows_logged:
            try:
                from cosim.logs.plot import plot_run

                log.info("plot: %s", plot_run(out))
            except Exception as e:  # a plot must never lose a finished run
                log.warning("could not write track.png: %s", e)
        return RunResult(out, reason, tick, summary, error)

    def _parts(self, pool: Pool, events: EventLog, states_log: StateLog, ids: list[str],
               total: int) -> tuple[list[Any], list[Any], list[Any], StateLogger,
                                    StatusEvents]:
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

            self.mavlink = MavlinkLinks(scn.vehicles, hz, self.mavlink_config, tlog_dir=self.out)
            for url, specs, (host, port) in zip(self.mavlink.urls, self.mavlink.specs,
                                                 self.mavlink.local_addresses):
                if url is not None:
                    log.info("MAVLink: vehicles %s..%s (system ids 1..%d) on %s (local %s:%d)",
                             ids[specs[0].row], ids[specs[-1].row], len(specs), url, host,
                             port)
            mav_part = parts.MavlinkPart(self.mavlink, commander, events, ids)
            before.append(mav_part.before_step)
            during.append(mav_part.on_exchange)
        if commander.active:
            before.append(parts.Guidance(commander, events, ids).before_step)
        self.participants = build_participants(
            scn, skip=("swarm",) if self.external_controller else ())
        ctx = RunContext(scn, self.out, ids, scn.origin.frame, start_ned, hz,
                         scn.rates.control_every, events, self.mavlink, pool.workers)
        for part in self.participants:
            part.start(ctx)
            during.append(part.on_exchange)
        index = {f.name: j for j, f in enumerate(pool.layout)}
        status_events = parts.StatusEvents(scn, index, events, ids)
        logger = parts.StateLogger(states_log, scn.rates.log_every, commander)
        after = [status_events.after_step, logger.after_step,
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
