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
from cosim.fdm_pool import STATE_INDEX, VehicleStatus, make_pool
from cosim.fdm_pool.base import Pool
from cosim.guidance import FixedWingGuidance
from cosim.logs import DiskReserve, EventLog, StateLog, clear_outputs, write_json_atomic
from cosim.scenario import Scenario
from cosim.sync.pacing import Pacer
from cosim.sync.participants import (
    Participant,
    ParticipantFailed,
    RunContext,
    build_participants,
    needs_mavlink,
)

log = logging.getLogger(__name__)

ProgressFn = Callable[[int, int], None]
_STATUS = STATE_INDEX["status"]
_EVENT_OF_STATUS = {VehicleStatus.GROUND_IMPACT: "ground_impact",
                    VehicleStatus.DIVERGED: "divergence"}
#: flag columns whose changes are events: column -> (event, on, off)
_FLAG_EVENTS = {
    "stalled": ("stall", "onset", "recovery"),
    "stall_protection_active": ("stall_protection", "active", "inactive"),
}
_FLAG_COLS = [STATE_INDEX[c] for c in _FLAG_EVENTS]
_FLAG_KINDS = tuple(_FLAG_EVENTS.values())  # by column of _FLAG_COLS
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
        states_log = StateLog(out / "states.parquet", ids, scn.origin.frame, hz)
        k, every_log, total = scn.rates.control_every, scn.rates.log_every, scn.total_ticks
        channels = scn.channels
        chan_index = {c: i for i, c in enumerate(channels)}
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
            pool = make_pool(scn.vehicles, scn.rates.dt_s, channels, self.backend, self.workers)
            with pool:  # closed however the rest of the set-up ends
                self._building = False
                self.pool = pool
                workers_used = pool.workers
                startup_s = time.perf_counter() - wall0
                log.info("%d vehicles ready in %.2f s on %d worker(s)", len(ids), startup_s,
                         workers_used)
                start_ned = np.stack(scn.origin.frame.geodetic_to_ned(
                    [v.lat_deg for v in scn.vehicles], [v.lon_deg for v in scn.vehicles],
                    [v.alt_msl_m for v in scn.vehicles]), axis=1)
                start_ne = start_ned[:, :2].copy()
                guidance = FixedWingGuidance(len(ids), scn.origin.frame, start_ne, chan_index) \
                    if scn.autopilot else None
                labels = guidance.labels if guidance is not None else None
                if self.mavlink_config is not None:
                    from cosim.mavlink import MavlinkLinks

                    self.mavlink = MavlinkLinks(scn.vehicles, hz, self.mavlink_config,
                                                tlog_dir=out, autopilot=scn.autopilot)
                    for url, specs, (host, port) in zip(self.mavlink.urls, self.mavlink.specs,
                                                         self.mavlink.local_addresses):
                        if url is not None:
                            log.info("MAVLink: vehicles %s..%s (system ids 1..%d) on %s "
                                     "(local %s:%d)", ids[specs[0].row], ids[specs[-1].row],
                                     len(specs), url, host, port)
                self.participants = build_participants(
                    scn, skip=("swarm",) if self.external_controller else ())
                ctx = RunContext(scn, out, ids, scn.origin.frame, start_ned, hz, k, events,
                                 self.mavlink, workers_used)
                for part in self.participants:
                    part.start(ctx)
                states = pool.states
                status = states[:, _STATUS].copy()
                flags = states[:, _FLAG_COLS].copy()
                self._status_events(events, 0, states, np.zeros_like(status), ids)
                states_log.append(0, states, labels)
                pending = [item for item in scn.schedule if item.tick < total]
                loop0 = time.perf_counter()
                if self.pacer:
                    self.pacer.start()
                while tick < total:
                    if self._stop.is_set():
                        reason = self._stop_reason
                        break
                    while pending and pending[0].tick <= tick:
                        item = pending.pop(0)
                        rows = list(item.vehicles)
                        for name, value in item.sets:
                            pool.setpoints[rows, chan_index[name]] = value
                        if item.command is not None and guidance is not None:
                            if self.mavlink is not None:  # the vehicles' MAVLink state follows
                                for r in rows:
                                    self.mavlink.local_command(r, item.command)
                            guidance.command(rows, item.command, states, pool.setpoints)
                        events.emit("schedule", tick, vehicle=None, vehicles=len(rows),
                                    **({"set": dict(item.sets)} if item.sets else {}),
                                    **({"command": item.command.source} if item.command else {}))
                    if self.mavlink is not None:  # the same command path as the schedule
                        for vc in self.mavlink.receive(tick, states):
                            if guidance is not None:
                                guidance.command([vc.row], vc.command, states, pool.setpoints)
                            events.emit("mavlink_command", tick, vehicle=ids[vc.row],
                                        origin=vc.origin, command=vc.command.source)
                    if guidance is not None:
                        for ge in guidance.update(states, pool.setpoints):
                            events.emit(ge.kind, tick, vehicle=ids[ge.vehicle], **ge.fields)
                    # telemetry and participants work on the states at ``tick`` while
                    # the workers step (they see a copy: the step overwrites ``states``)
                    at_tick = states.copy() if self.participants else states
                    pool.send(k)
                    if self.mavlink is not None:
                        self.mavlink.send_telemetry(tick)
                    for part in self.participants:
                        part.on_exchange(tick, at_tick)
                    states = pool.wait(self.step_timeout_s)
                    tick += k
                    new_status = states[:, _STATUS]
                    if not np.array_equal(new_status, status):
                        self._status_events(events, tick, states, status, ids)
                        status = new_status.copy()
                    new_flags = states[:, _FLAG_COLS]
                    if not np.array_equal(new_flags, flags):
                        self._flag_events(events, tick, new_flags, flags, ids)
                        flags = new_flags.copy()
                    if tick % every_log == 0:
                        states_log.append(tick, states, labels)
                    if self.pacer:
                        self.pacer.pace(tick / hz)
                    if self.progress:
                        self.progress(tick, total)
                else:
                    reason = "completed"
                if states_log.last_tick != tick:  # the tick the run ends on, once
                    states_log.append(tick, states, labels)
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

    def _status_events(self, events: EventLog, tick: int, states: np.ndarray,
                       old: np.ndarray, ids: list[str]) -> None:
        for i in np.flatnonzero(states[:, _STATUS] != old).tolist():
            st = VehicleStatus(int(states[i, _STATUS]))
            if st in _EVENT_OF_STATUS:
                row = states[i]
                events.emit(_EVENT_OF_STATUS[st], tick, vehicle=ids[i],
                            lat_deg=row[STATE_INDEX["lat_deg"]],
                            lon_deg=row[STATE_INDEX["lon_deg"]],
                            alt_msl_m=row[STATE_INDEX["alt_msl_m"]],
                            vd_mps=row[STATE_INDEX["vd_mps"]],
                            airspeed_mps=row[STATE_INDEX["airspeed_mps"]])
                log.warning("tick %d: vehicle %s: %s (frozen)", tick, ids[i],
                            _EVENT_OF_STATUS[st])

    def _flag_events(self, events: EventLog, tick: int, new: np.ndarray, old: np.ndarray,
                     ids: list[str]) -> None:
        for i, j in np.argwhere(new != old).tolist():
            kind, on, off = _FLAG_KINDS[j]
            events.emit(kind, tick, vehicle=ids[i], phase=on if new[i, j] else off)

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
