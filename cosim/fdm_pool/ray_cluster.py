"""The ``ray`` backend: the vehicles sharded over the machines of a Ray cluster.

Hierarchical: one *agent* (a Ray actor) per machine runs an ordinary
``process`` pool over that machine's share of the vehicles, in shared memory
as on one machine; the driver makes one call per agent per exchange, carrying
its setpoints out and its states back. A Ray call costs about a millisecond
(1.4 ms with a 256-aircraft state block on the 2-core test machine), so never
one actor per vehicle or per core. The driver's own machine, when it is a
node of the cluster, needs no agent: its share is a process pool of the
driver, stepped while the agents step theirs, as the process backend's
driver steps its own shard (``local_share=False`` puts it behind an agent
like the others, which is what ``benchmarks/ray_efficiency.py`` uses to
measure what a remote machine costs).

Layout: ``workers`` (default: every CPU of the cluster's live machines) are
spread over the machines, the head first, then by node id, at most as many
on a machine as it has CPUs while the cluster has room; the vehicles are
split over the workers as the ``process`` backend splits them, and each
machine's agent takes its workers' contiguous share. Each agent reserves
its workers' CPUs on its machine (``num_cpus``), so two runs' agents do not
share cores unknowingly; the driver's own share reserves none (it runs in
the driver's process, outside Ray's accounting). States do not depend on
any of this.

Joining the cluster (bounded, interruptible) is ``ray_connect``'s; the agent
each machine runs is ``ray_agent``'s.

Faults: a lost agent (its process killed, its machine gone) is killed for
good (it may only be unreachable) and replaced, and so is one of whose
worker processes died (the OS killed it, it crashed): its surviving workers
are stopped first. A new agent, on the same machine if Ray still lists it,
else on the live machine with the most CPUs, rebuilds its vehicles from the
last states gathered (``cosim.vehicles.resume``: the agents gather, beside
each state row, the body rates, controls and autopilot integrators, so a
JSBSim vehicle goes on where and as it was; a batched one from its position,
heading and speed) and is sent the last value of every channel; its frozen
vehicles stay frozen in their rows (an agent left with none is not
replaced). A replacement lost too stops the run. The run is no longer
bit-exact from that exchange on, and a ``pool_recovered`` notice says so,
with the machine, node, agent, cause and vehicles (the run logs it as an
event). ``strict=True`` stops instead, with an ``AgentLost`` or a
``MachineWorkerDied`` naming the machine. A worker process of the driver's
own share lost stops the run with a ``MachineWorkerDied``, as in the process
backend: a process killed beside the driver (by the OOM killer, by hand)
is the run's own machine failing, which a rebuild there would only repeat.
Closing the pool stops every agent's worker processes and
then the agent: nothing is left running on any machine.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import socket
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from cosim.core.state import STATE_INDEX, VehicleSpec, VehicleStatus
from cosim.errors import (
    AgentLost,
    BuildError,
    ConfigError,
    MachineWorkerDied,
    WorkerDied,
    WorkerTimeout,
    how_it_ended,
)
from cosim.fdm_pool.base import Pool, Watch
from cosim.fdm_pool.process import ProcessPool, default_workers, shard_bounds
from cosim.fdm_pool.ray_agent import Agent, remote_cause, why_lost
from cosim.fdm_pool.ray_connect import (
    CONNECT_TIMEOUT_S,
    Node,
    connect,
    import_ray,
    live_nodes,
)
from cosim.vehicles.resume import FIELDS as RESUME_FIELDS
from cosim.vehicles.resume import NOT_RESTORED, RESTORED, resume_spec

log = logging.getLogger(__name__)

_STOP_TIMEOUT_S = 10.0
_PATIENCE_S = 30.0  # a build this long on an agent is logged


def plan(nodes: Sequence[Node], n: int, workers: int) -> list[tuple[Node, int, int, int]]:
    """``(node, workers, first row, end row)`` per agent: each node given up
    to its CPUs, in order, while workers last (more workers than CPUs: one
    more each in turn), the rows split per worker as the process backend
    does; nodes given no worker have no agent."""
    if not nodes:
        raise ConfigError("the Ray cluster has no live machine with a CPU")
    count, left = [], workers
    for node in nodes:  # each machine up to its CPUs, the head first
        count.append(min(left, node.cpus))
        left -= count[-1]
    for k in range(left):  # more workers than CPUs: one more each, in turn
        count[k % len(count)] += 1
    bounds = shard_bounds(n, workers)
    out, w0 = [], 0
    for node, c in zip(nodes, count):
        if c:
            out.append((node, c, bounds[w0][0], bounds[w0 + c - 1][1]))
            w0 += c
    return out


@dataclasses.dataclass
class _Share:
    """One agent and what it holds."""

    handle: Any
    node: Node
    workers: int
    rows: Any  # slice or index array of the run's rows
    watch: Watch | None = None  # the pool's watch, for these rows
    watch_js: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, np.intp))
    pid: int = 0
    host: str = ""
    busy: list[float] = dataclasses.field(default_factory=list)


class RayPool(Pool):
    """The vehicles sharded over the machines of a Ray cluster (one agent per
    machine running a local process pool)."""

    backend = "ray"

    @classmethod
    def default_workers(cls) -> int:
        """Every CPU of the cluster once joined; before that, this machine's."""
        try:
            import ray
        except ImportError:
            return default_workers()
        if ray.is_initialized():
            return max(1, int(ray.cluster_resources().get("CPU", 1)))
        return default_workers()

    @classmethod
    def available(cls) -> None:
        import_ray()

    def __init__(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str] = (),
                 workers: int | None = None, address: str | None = None,
                 strict: bool = False, local_share: bool = True,
                 start_timeout_s: float | None = None, watch: Watch | None = None,
                 connect_timeout_s: float | None = None) -> None:
        super().__init__(specs, dt_s, channels, watch=watch)
        ray = import_ray()
        if workers is not None and int(workers) < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.strict = bool(strict)
        self.address = connect(address, CONNECT_TIMEOUT_S if connect_timeout_s is None
                               else float(connect_timeout_s))
        nodes = live_nodes()
        w = (sum(n.cpus for n in nodes) if workers is None else int(workers))
        w = max(1, min(w, self.n))
        self._n_workers = w
        self._timeout_s = start_timeout_s if start_timeout_s is not None else 120.0 + 0.05 * self.n
        self._agent_cls = ray.remote(Agent)
        self._shares: list[_Share] = []
        #: the driver's own machine's share, stepped in this process (no agent)
        self._local: ProcessPool | None = None
        self._local_rows: Any = slice(0, 0)
        self._local_node: Node | None = None
        self._local_js = np.zeros(0, dtype=np.intp)
        self._refs: list[Any] = []
        #: the agents' states have the ``resume`` columns after the run's own
        self._agent_layout = (*self.layout, *RESUME_FIELDS)
        #: each vehicle's last ``resume`` columns, from its agent (for a rebuild)
        self._resume = np.full((self.n, len(RESUME_FIELDS)), np.nan)
        #: the last value sent on each channel of each vehicle, up to the last
        #: exchange finished, and this exchange's (for a rebuild)
        self._latched = np.full((self.n, len(self.channels)), np.nan)
        self._sent = np.full((self.n, len(self.channels)), np.nan)
        self._frozen = np.zeros(self.n, dtype=bool)  # rows kept as they are after a rebuild
        self._frozen_rows: np.ndarray | None = None
        self._frozen_states = np.zeros((0, len(self.layout)))
        here = ray.get_runtime_context().get_node_id() if local_share else None
        try:
            local_job = None
            for node, nw, a, b in plan(nodes, self.n, w):
                if node.id == here:
                    local_job = (node, nw, slice(a, b))
                else:
                    share = _Share(self._spawn(node, nw, soft=False), node, nw, slice(a, b))
                    share.watch, share.watch_js = self._part(np.arange(a, b))
                    self._shares.append(share)
            self._build([(s, self.specs[s.rows], None) for s in self._shares], local_job)
        except BaseException:
            self._close()
            raise
        where = [f"{s.node.ip} ({s.workers})" for s in self._shares]
        if self._local is not None and self._local_node is not None:
            where.insert(0, f"{self._local_node.ip} ({self._local.workers}, in this process)")
        log.info("ray backend: %d vehicles on %d machine(s), %d worker(s): %s", self.n,
                 len(where), w, ", ".join(where))

    # -- the contract -------------------------------------------------------

    @property
    def workers(self) -> int:
        return self._n_workers

    @property
    def machines(self) -> list[str]:
        """The machines in use (node IPs): the driver's own first if it has a
        share, then each agent's."""
        own = [self._local_node.ip] if self._local_node is not None else []
        return own + [s.node.ip for s in self._shares]

    @property
    def agents(self) -> dict[int, int]:
        """Agent index -> pid of the agent's process (on its own machine)."""
        return {i: s.pid for i, s in enumerate(self._shares) if s.handle is not None}

    @property
    def agent_vehicles(self) -> dict[int, list[str]]:
        """Agent index -> the vehicles it steps."""
        return {i: self._ids_of(s) for i, s in enumerate(self._shares) if s.handle is not None}

    @property
    def pids(self) -> dict[int, int]:
        """Every process stepping vehicles that the driver answers for: the
        worker processes of its own machine's share, then each agent."""
        own = list(self._local.pids.values()) if self._local is not None else []
        return dict(enumerate(own + [s.pid for s in self._shares if s.handle is not None]))

    def busy_s(self) -> list[float]:
        own = self._local.busy_s() if self._local is not None else []
        return own + [b for s in self._shares for b in s.busy]

    def _send(self, nsub: int) -> None:
        self._nsub = nsub
        sp = self.setpoints if self.channels else None
        if sp is not None:
            self._sent[:] = sp
        self._refs = [s.handle.step.remote(None if sp is None else sp[s.rows], nsub)
                      if s.handle is not None else None for s in self._shares]
        if self._local is not None:
            if sp is not None:
                self._local.setpoints[:] = sp[self._local_rows]
            self._local.send(nsub)

    def _wait(self, timeout_s: float | None) -> None:
        ray = import_ray()
        k = len(self.layout)
        m = self._nsub // self.watch.every if self.watch is not None else 0
        if self._local is not None:  # the agents step theirs meanwhile
            try:
                self.states[self._local_rows] = self._local.wait(timeout_s)
            except WorkerDied as e:
                raise self._local_fault(e) from None
            if len(self._local_js):
                self.watched[:m, self._local_js] = self._local.watched[:m]
        refs = self._refs
        live = [r for r in refs if r is not None]
        _, pending = ray.wait(live, num_returns=len(live), timeout=timeout_s)
        if pending:
            i = refs.index(pending[0])
            s = self._shares[i]
            assert timeout_s is not None
            raise WorkerTimeout(i, s.pid, self._ids_of(s), self.tick, timeout_s,
                                f"finish tick {self.tick + self._nsub} on {s.node.ip}")
        for i, ref in enumerate(refs):
            if ref is None:  # an agent whose vehicles are all frozen: nothing to step
                continue
            s = self._shares[i]
            try:
                block, s.busy, watched = ray.get(ref)
            except ray.exceptions.RayTaskError as e:
                cause = remote_cause(e)
                if type(cause) is not WorkerDied:  # a vehicle's failure, not the machine's
                    raise cause from None
                block, watched = self._replace(i, self._worker_fault(s, cause))
                s = self._shares[i]
            except ray.exceptions.RayActorError as e:
                block, watched = self._replace(i, AgentLost(
                    i, s.node.ip, s.node.id, s.pid, self._ids_of(s), self.tick, why_lost(e)))
                s = self._shares[i]  # its replacement, holding the survivors' rows
            self.states[s.rows] = block[:, :k]
            self._resume[s.rows] = block[:, k:]
            if watched is not None:
                self.watched[:m, s.watch_js] = watched[..., :k]
        if self._frozen_rows is not None:
            self.states[self._frozen_rows] = self._frozen_states
            if self.watch is not None:  # the frozen ones among the watched stay as they are
                frozen = self._frozen[list(self.watch.rows)]
                self.watched[:m, frozen] = self.states[np.asarray(self.watch.rows)[frozen]]
        if self.channels:  # the exchange is done: its setpoints are the last ones sent
            written = ~np.isnan(self._sent)
            self._latched[written] = self._sent[written]

    def _close(self) -> None:
        if self._local is not None:
            self._local.close()
            self._local = None
        if not self._shares:
            return
        ray = import_ray()
        stops = [s.handle.stop.remote() for s in self._shares if s.handle is not None]
        try:
            ray.wait(stops, num_returns=len(stops), timeout=_STOP_TIMEOUT_S)
        except Exception:  # an agent already gone: nothing of it to stop
            pass
        for s in self._shares:
            if s.handle is None:
                continue
            try:
                ray.kill(s.handle, no_restart=True)
            except Exception:
                pass
        self._await_gone([s.pid for s in self._shares if s.host == socket.gethostname()])
        self._shares.clear()
        self._refs = []

    # -- faults ---------------------------------------------------------------

    def _worker_fault(self, s: _Share, e: WorkerDied) -> MachineWorkerDied:
        """A worker process under agent ``s`` died (``e``, in its agent's
        numbering): the same, naming the machine."""
        return MachineWorkerDied(e.worker, e.pid, e.exitcode, e.vehicles, e.tick, s.node.ip,
                                 s.node.id, self._shares.index(s))

    def _local_fault(self, e: WorkerDied) -> WorkerDied:
        """A worker process of the driver's own share died: the same, naming
        this machine (a timeout stays as it is)."""
        if type(e) is not WorkerDied or self._local_node is None:
            return e
        return MachineWorkerDied(e.worker, e.pid, e.exitcode, e.vehicles, e.tick,
                                 self._local_node.ip, self._local_node.id, None)

    # -- building and rebuilding ---------------------------------------------

    def _spawn(self, node: Node, workers: int, soft: bool) -> Any:
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        return self._agent_cls.options(
            num_cpus=min(workers, node.cpus), max_restarts=0,
            scheduling_strategy=NodeAffinitySchedulingStrategy(node.id, soft=soft)).remote()

    def _build(self, jobs: list[tuple[_Share, list[VehicleSpec], np.ndarray | None]],
               local: tuple[Node, int, slice] | None = None) -> None:
        """Build every job's vehicles on its agent, and ``local``'s (node,
        workers, rows) in this process meanwhile; every vehicle that cannot
        be built, on any machine, is in one ``BuildError``."""
        ray = import_ray()
        layout = tuple(self.layout)
        k = len(layout)
        refs = [s.handle.build.remote(list(specs), self.dt_s, self.channels, s.workers,
                                      self._agent_layout, self.tick, sp, s.watch)
                for s, specs, sp in jobs]
        failures: list[tuple[str, str]] = []
        if local is not None:
            node, nw, rows = local
            self._local_node, self._local_rows = node, rows
            part, self._local_js = self._part(np.arange(self.n)[rows])
            try:
                self._local = ProcessPool(self.specs[rows], self.dt_s, self.channels,
                                          workers=nw, layout=layout, watch=part,
                                          start_timeout_s=self._timeout_s)
                self.states[rows] = self._local.states
            except BuildError as e:
                failures += e.failures
        deadline = time.monotonic() + self._timeout_s
        for (s, specs, _), ref in zip(jobs, refs):
            done, _ = ray.wait([ref], timeout=max(0.0, min(_PATIENCE_S,
                                                           deadline - time.monotonic())))
            if not done:  # not placed yet, or a long build: say which
                log.warning("ray backend: still waiting for machine %s to build %d vehicles "
                            "(its agent needs %d CPU(s) there; other Ray work may hold them)",
                            s.node.ip, len(specs), min(s.workers, s.node.cpus))
                done, _ = ray.wait([ref], timeout=max(0.0, deadline - time.monotonic()))
            if not done:
                raise WorkerTimeout(self._shares.index(s), None, [v.id for v in specs],
                                    self.tick, self._timeout_s,
                                    f"build and trim its vehicles on {s.node.ip}")
            try:
                block, s.pid, s.host = ray.get(ref)
            except ray.exceptions.RayTaskError as e:
                cause = remote_cause(e)
                if type(cause) is WorkerDied:
                    raise self._worker_fault(s, cause) from None
                if not isinstance(cause, BuildError):
                    raise cause from None
                failures += cause.failures
                continue
            except ray.exceptions.RayActorError as e:
                raise AgentLost(self._shares.index(s), s.node.ip, s.node.id, s.pid,
                                [v.id for v in specs], self.tick, why_lost(e)) from None
            self.states[s.rows] = block[:, :k]
            self._resume[s.rows] = block[:, k:]
        if failures:
            order = {v: k for k, v in enumerate(self.ids)}
            raise BuildError(sorted(failures, key=lambda f: order.get(f[0], 0)), self.n)

    def _replace(self, i: int, fault: WorkerDied) -> tuple[np.ndarray, np.ndarray | None]:
        """Agent ``i``'s share is lost (``fault``: the agent, ``AgentLost``, or
        a worker process of it, ``MachineWorkerDied``): stop (``strict``) or
        rebuild its vehicles from their last states on a new agent and run
        this exchange there."""
        old = self._shares[i]
        if self.strict:
            raise fault
        log.warning("%s; rebuilding its machine's vehicles from their last states (the run is "
                    "no longer bit-exact)", fault)
        rows = np.arange(self.n)[old.rows]
        status = self.states[rows, STATE_INDEX["status"]]
        alive = rows[status == VehicleStatus.ACTIVE]
        frozen = rows[status != VehicleStatus.ACTIVE]
        if len(frozen):
            self._frozen[frozen] = True
            self._frozen_rows = np.flatnonzero(self._frozen)
            self._frozen_states = self.states[self._frozen_rows].copy()
        ray = import_ray()
        if isinstance(fault, MachineWorkerDied):  # the agent lives: its other workers first
            try:
                ray.get(old.handle.stop.remote(), timeout=_STOP_TIMEOUT_S)
            except Exception:  # gone meanwhile, or stuck: killed next all the same
                pass
        try:  # it may only be unreachable: it must not go on holding CPUs and workers
            ray.kill(old.handle, no_restart=True)
        except Exception:
            pass
        reason = (fault.reason if isinstance(fault, AgentLost) else
                  f"its worker {fault.worker} (pid {fault.pid} there) "
                  f"{how_it_ended(fault.exitcode)}; that worker's vehicles: "
                  f"{', '.join(fault.vehicles)}")
        ids = [self.ids[r] for r in alive.tolist()]
        frozen_ids = [self.ids[r] for r in frozen.tolist()]
        self.notices.append(("pool_recovered", {
            "machine": old.node.ip, "node": old.node.id, "agent": i,
            "cause": "agent_lost" if isinstance(fault, AgentLost) else "worker_died",
            "reason": reason, "vehicles": len(alive), "vehicle_ids": ids,
            "frozen": len(frozen), "frozen_ids": frozen_ids, "bit_exact": False,
            "restored": list(RESTORED), "not_restored": list(NOT_RESTORED)}))
        if not len(alive):  # nothing left to fly there: no agent
            self._shares[i] = _Share(None, old.node, 0, alive)
            return np.zeros((0, len(self._agent_layout))), None
        nodes = {n.id: n for n in live_nodes()}
        if not nodes:
            raise AgentLost(i, old.node.ip, old.node.id, old.pid, self._ids_of(old), self.tick,
                            f"{reason}; no live machine is left to rebuild its vehicles on")
        node = nodes.get(old.node.id) or max(nodes.values(), key=lambda n: n.cpus)
        self.notices[-1][1]["replaced_on"] = node.ip
        workers = min(old.workers, len(alive))
        share = _Share(self._spawn(node, workers, soft=True), node, workers, alive)
        share.watch, share.watch_js = self._part(alive)
        self._shares[i] = share
        specs = [resume_spec(self.specs[r], self.states[r], self._resume[r], self.channels,
                             self._latched[r]) for r in alive.tolist()]
        # this exchange's setpoints, applied as it starts; a vehicle not restored
        # from its properties (a batched one) is sent every channel's last value too
        sent = None
        if self.channels:
            sent = self._sent[alive].copy()
            again = np.array([not spec.resume for spec in specs])
            earlier = self._latched[alive][again]
            sent[again] = np.where(np.isnan(sent[again]), earlier, sent[again])
        self._build([(share, specs, sent)])
        try:  # one chance: a replacement lost too stops the run
            block, share.busy, watched = ray.get(share.handle.step.remote(None, self._nsub),
                                                 timeout=self._timeout_s)
        except ray.exceptions.RayTaskError as err:
            cause = remote_cause(err)
            raise (self._worker_fault(share, cause) if type(cause) is WorkerDied
                   else cause) from None
        except ray.exceptions.RayActorError as err:
            raise AgentLost(i, node.ip, node.id, share.pid, self._ids_of(share), self.tick,
                            f"its replacement was lost too: {why_lost(err)}") from None
        except ray.exceptions.GetTimeoutError:
            raise WorkerTimeout(i, share.pid, self._ids_of(share), self.tick, self._timeout_s,
                                f"finish tick {self.tick + self._nsub} on {node.ip} after "
                                f"a rebuild") from None
        return np.asarray(block), watched

    def _part(self, rows: np.ndarray) -> tuple[Watch | None, np.ndarray]:
        """The watch for a share holding ``rows`` (``Watch.part``)."""
        if self.watch is None:
            return None, np.zeros(0, dtype=np.intp)
        return self.watch.part(rows.tolist())

    def _ids_of(self, s: _Share) -> list[str]:
        return [self.ids[r] for r in np.arange(self.n)[s.rows].tolist()]

    @staticmethod
    def _await_gone(pids: list[int], timeout_s: float = 5.0) -> None:
        """Wait until the agents on this machine have exited (``ray.kill``
        returns before they have)."""
        deadline = time.monotonic() + timeout_s
        for pid in pids:
            while time.monotonic() < deadline:
                try:
                    os.kill(pid, 0)
                except (ProcessLookupError, PermissionError):
                    break
                time.sleep(0.02)
