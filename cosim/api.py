"""The Python entry point: ``cosim.run(scenario, out=...)`` does what ``cosim
run`` does and returns its result.

Worker processes are started by *spawning* a fresh interpreter, which imports
the calling script again before it runs its worker: a script that calls
``cosim.run`` must keep the call under ``if __name__ == "__main__":``. Called
while a worker process is still starting (the guard is missing), it raises
``GuardMissing`` at once with that advice instead of letting every worker
start more workers.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.errors import ConfigError, CosimError

if TYPE_CHECKING:
    from cosim.scenario import Scenario
    from cosim.sync import RunResult


class GuardMissing(CosimError, RuntimeError):
    """``cosim.run`` called from a module a worker process is importing."""


def _starting_worker() -> bool:
    """Whether this process is a spawned child still importing its parent's
    script (multiprocessing's own "bootstrapping" flag, the one its error
    about starting processes too early reads)."""
    import multiprocessing.process

    return bool(getattr(multiprocessing.process.current_process(), "_inheriting", False))


def run(scenario: str | Path | Scenario, out: str | Path | None = None, *,
        duration_s: float | None = None, overwrite: bool = False, **options: Any) -> RunResult:
    """Run a scenario (a file's path or a loaded ``Scenario``) into ``out``
    (default ``runs/<name>-<date>-<time>``, as ``cosim run``); ``options`` are
    those of ``cosim.sync.Run``: ``backend``, ``workers``, ``realtime``,
    ``mavlink``, ``progress``, ... Returns the run's ``RunResult`` (its
    ``summary``, ``stop_reason``, ``out_dir``, ``error``)."""
    if _starting_worker():
        raise GuardMissing(
            "cosim.run() was called while a worker process was starting: cosim's workers "
            "import the calling script again, so keep the call under "
            "`if __name__ == \"__main__\":` (see examples/run_from_python.py)")
    import time

    from cosim.scenario import load_scenario
    from cosim.sync import run_scenario

    scn = scenario if not isinstance(scenario, (str, Path)) else load_scenario(scenario)
    if duration_s is not None:
        scn = scn.with_duration(duration_s)
    folder = Path(out) if out is not None else Path("runs") / (
        f"{scn.folder_name}-{time.strftime('%Y%m%d-%H%M%S')}")
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"out {folder}: exists and is not a folder")
    if ((folder / "summary.json").exists() or (folder / "events.jsonl").exists()) \
            and not overwrite:
        raise ConfigError(f"{folder} already holds a run; choose another out or pass "
                          f"overwrite=True")  # the run clears it: never mixed with the new one
    return run_scenario(scn, folder, **options)
