"""The CosimError family.

Every error cosim raises on purpose derives from ``CosimError``. All of them
pickle (they pass ``args`` to ``super().__init__``) so a worker process can
send one to the driver intact.
"""

from __future__ import annotations

from pathlib import Path


class CosimError(Exception):
    """Base class of every error cosim raises on purpose."""


def install_extra(extra: str) -> str:
    """The command that installs cosim's optional ``extra`` (e.g. "ray") the
    way this cosim was installed: from its checkout (``pip install -e
    '/path/to/cosim[ray]'``) or from a package index (``pip install
    'cosim[ray]'``)."""
    root = Path(__file__).resolve().parent.parent
    if (root / "pyproject.toml").is_file() and (root / "cosim").is_dir():
        return f"pip install -e '{root}[{extra}]'"
    return f"pip install 'cosim[{extra}]'"


class ConfigError(CosimError):
    """A scenario (or command-line value) is invalid.

    ``problems`` holds the problems found, each already formatted as
    ``file:line: path: message``; ``more`` counts those found but not kept.
    ``str()`` lists the first ``SHOWN`` one per line, then how many more
    there are (a file with thousands of mistakes prints a screenful).
    """

    SHOWN = 50

    def __init__(self, problems: list[str] | str, more: int = 0) -> None:
        if isinstance(problems, str):
            problems = [problems]
        super().__init__(problems, more)
        self.problems = list(problems)
        self.more = more

    @property
    def count(self) -> int:
        """Every problem found (kept and not)."""
        return len(self.problems) + self.more

    def __str__(self) -> str:
        shown = self.problems[:self.SHOWN]
        rest = self.count - len(shown)
        if rest > 0:
            shown = [*shown, f"... and {rest} more problem{'s' if rest > 1 else ''} "
                             f"({self.count} in all)"]
        return "\n".join(shown)


class ModelNotFound(ConfigError):
    """An aircraft model name matches no model on the search path."""


class JSBSimError(CosimError):
    """A JSBSim call failed (returned False or raised); ``vehicle`` names the
    vehicle when there is one (its message names it too)."""

    def __init__(self, message: str, vehicle: str | None = None) -> None:
        super().__init__(message, vehicle)
        self.message = message
        self.vehicle = vehicle

    def __str__(self) -> str:
        return self.message


class BuildError(CosimError):
    """Vehicles could not be built or trimmed: every one of them, found in one
    pass over all vehicles (and all workers). ``failures``: (vehicle id,
    message naming its model and settings), in vehicle order."""

    SHOWN = 20

    def __init__(self, failures: list[tuple[str, str]], total: int | None = None) -> None:
        super().__init__(failures, total)
        self.failures = list(failures)
        self.total = total

    @property
    def vehicles(self) -> list[str]:
        return [v for v, _ in self.failures]

    def __str__(self) -> str:
        n = len(self.failures)
        of = f" of {self.total}" if self.total is not None else ""
        plural = "s" if n != 1 or self.total is not None else ""
        lines = [f"{n}{of} vehicle{plural} could not be built and trimmed "
                 f"(try another airspeed or altitude, or trim: false):"]
        # vehicles that failed for the same reason are one line
        same: dict[str, list[str]] = {}
        for vid, msg in self.failures:
            head = f"vehicle {vid!r}"
            key = "\0" + msg[len(head):] if msg.startswith(head) else msg
            same.setdefault(key, []).append(vid)
        for msg, ids in list(same.items())[:self.SHOWN]:
            if not msg.startswith("\0") or len(ids) == 1:
                lines += [f"  {msg.replace(chr(0), f'vehicle {v!r}', 1)}" for v in ids]
                continue
            shown = ", ".join(ids[:8]) + (f", ... ({len(ids)} in all)" if len(ids) > 8 else "")
            lines.append(f"  vehicles {shown}{msg[1:]}")
        if len(same) > self.SHOWN:
            lines.append(f"  ... and {len(same) - self.SHOWN} more")
        return "\n".join(lines)


class VehicleError(CosimError):
    """Applying setpoints to or stepping one vehicle failed during an exchange
    (a JSBSim call returned False or raised, or anything else went wrong).

    Raised by the shard that owns the vehicle, whichever backend it runs in;
    in a worker process it reaches the driver inside a ``WorkerError``.
    ``tick`` is the physics tick the exchange started from.
    """

    def __init__(self, vehicle: str | None, tick: int | None, message: str) -> None:
        super().__init__(vehicle, tick, message)
        self.vehicle = vehicle
        self.tick = tick
        self.message = message

    def __str__(self) -> str:
        where = f"vehicle {self.vehicle!r}" if self.vehicle is not None else "a vehicle"
        at = f" at tick {self.tick}" if self.tick is not None else ""
        return f"{where}{at}: {self.message}"


class PoolStateError(CosimError):
    """A pool method was called in a state that does not allow it."""


class WorkerError(CosimError):
    """A worker raised an exception; carries the vehicle, tick and remote traceback."""

    def __init__(self, worker: int, vehicle: str | None, tick: int | None, remote_tb: str) -> None:
        super().__init__(worker, vehicle, tick, remote_tb)
        self.worker = worker
        self.vehicle = vehicle
        self.tick = tick
        self.remote_traceback = remote_tb

    def __str__(self) -> str:
        where = f"worker {self.worker}"
        if self.vehicle is not None:
            where += f", vehicle {self.vehicle!r}"
        if self.tick is not None:
            where += f", tick {self.tick}"
        last = self.remote_traceback.strip().splitlines()[-1:] or ["?"]
        return f"{where}: {last[0]}\n--- remote traceback ---\n{self.remote_traceback.rstrip()}"


def _vehicle_list(vehicles: list[str], shown: int = 10) -> str:
    """``a, b, c`` or, for long lists, ``a, b, ... (N in all)``."""
    text = ", ".join(vehicles[:shown])
    if len(vehicles) > shown:
        text += f", ... ({len(vehicles)} in all)"
    return text


def how_it_ended(exitcode: int | None) -> str:
    """``killed by SIGKILL`` or ``exited with code 3`` for a process's exit code."""
    import signal

    if exitcode is not None and exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


class WorkerDied(CosimError):
    """A worker process ended without being asked to (killed by the OS, crashed)."""

    def __init__(self, worker: int, pid: int | None, exitcode: int | None,
                 vehicles: list[str], tick: int | None) -> None:
        super().__init__(worker, pid, exitcode, vehicles, tick)
        self.worker = worker
        self.pid = pid
        self.exitcode = exitcode
        self.vehicles = list(vehicles)
        self.tick = tick

    def __str__(self) -> str:
        at = f" at tick {self.tick}" if self.tick is not None else ""
        return (f"worker {self.worker} (pid {self.pid}) {how_it_ended(self.exitcode)}{at}; "
                f"its vehicles: {_vehicle_list(self.vehicles)}")


class AgentLost(WorkerDied):
    """A machine's agent of a cluster backend is gone (its process killed, its
    machine down or cut off): names the machine and what Ray said."""

    def __init__(self, worker: int, machine: str, node_id: str, pid: int | None,
                 vehicles: list[str], tick: int | None, reason: str) -> None:
        CosimError.__init__(self, worker, machine, node_id, pid, vehicles, tick, reason)
        self.worker = worker
        self.machine = machine
        self.node_id = node_id
        self.pid = pid
        self.exitcode = None
        self.vehicles = list(vehicles)
        self.tick = tick
        self.reason = reason

    def __str__(self) -> str:
        at = f" at tick {self.tick}" if self.tick is not None else ""
        return (f"agent {self.worker} on machine {self.machine} (node {self.node_id[:12]}, "
                f"pid {self.pid}) was lost{at}: {self.reason}; its vehicles: "
                f"{_vehicle_list(self.vehicles)}")


class MachineWorkerDied(WorkerDied):
    """A worker process on one machine of a cluster backend ended without being
    asked to: ``worker`` and ``pid`` are that machine's (every machine has a
    worker 1), so the machine, its node and its agent (``None``: the share
    the driver steps itself) are named beside them."""

    def __init__(self, worker: int, pid: int | None, exitcode: int | None,
                 vehicles: list[str], tick: int | None, machine: str, node_id: str,
                 agent: int | None) -> None:
        super().__init__(worker, pid, exitcode, vehicles, tick)
        self.args = (worker, pid, exitcode, vehicles, tick, machine, node_id, agent)  # pickled
        self.machine = machine
        self.node_id = node_id
        self.agent = agent

    def __str__(self) -> str:
        at = f" at tick {self.tick}" if self.tick is not None else ""
        whose = f"agent {self.agent}" if self.agent is not None else "the driver's own share"
        return (f"worker {self.worker} (pid {self.pid}) on machine {self.machine} (node "
                f"{self.node_id[:12]}, {whose}) {how_it_ended(self.exitcode)}{at}; its "
                f"vehicles: {_vehicle_list(self.vehicles)}")


class ClusterUnreachable(CosimError):
    """The cluster a backend was told to join did not accept this process
    (nothing listening, no answer in time, refused): names the address and
    what to check."""


class WorkerTimeout(WorkerDied):
    """A worker is alive but did not answer within the deadline (stuck, stopped)."""

    def __init__(self, worker: int, pid: int | None, vehicles: list[str], tick: int | None,
                 timeout_s: float, what: str) -> None:
        CosimError.__init__(self, worker, pid, vehicles, tick, timeout_s, what)
        self.worker = worker
        self.pid = pid
        self.exitcode = None
        self.vehicles = list(vehicles)
        self.tick = tick
        self.timeout_s = timeout_s
        self.what = what

    def __str__(self) -> str:
        return (f"worker {self.worker} (pid {self.pid}) did not {self.what} within "
                f"{self.timeout_s:g} s; its vehicles: {_vehicle_list(self.vehicles)}")
