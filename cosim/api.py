"""The Python entry point: ``cosim.run(scenario, out=...)`` does what ``cosim
run`` does and returns its result; ``prepare_run`` builds the run both use
from the same options (the run folder, MAVLink and its signing, an outside
controller, the live view, video streams, the backend's own options).

Worker processes are started by *spawning* a fresh interpreter, which imports
the calling script again before it runs its worker: a script that calls
``cosim.run`` must keep the call under ``if __name__ == "__main__":``. Called
while a worker process is still starting (the guard is missing), it raises
``GuardMissing`` at once with that advice instead of letting every worker
start more workers.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.errors import ConfigError, CosimError

if TYPE_CHECKING:
    from cosim.scenario import Scenario
    from cosim.sync import Run, RunResult


class GuardMissing(CosimError, RuntimeError):
    """``cosim.run`` called from a module a worker process is importing."""


def _starting_worker() -> bool:
    """Whether this process is a spawned child still importing its parent's
    script (multiprocessing's own "bootstrapping" flag, the one its error
    about starting processes too early reads)."""
    import multiprocessing.process

    return bool(getattr(multiprocessing.process.current_process(), "_inheriting", False))


#: the options' names in ``prepare_run``'s messages, unless the caller gives its own
PYTHON_NAMES = {"out": "out", "overwrite": "overwrite=True", "mavlink_url": "mavlink_url",
                "signing": "signing_key_file (or signing_key_env)",
                "external_controller": "external_controller"}


def run(scenario: str | Path | Scenario, out: str | Path | None = None, **options: Any
        ) -> RunResult:
    """Run a scenario (a file's path or a loaded ``Scenario``) into ``out``
    (default ``runs/<name>-<date>-<time>``, as ``cosim run``) with the options
    of ``prepare_run`` (``duration_s``, ``overwrite``, ``mavlink_url``,
    ``signing_key_file``, ``external_controller``, ``view``, ``video``, ...)
    and those of ``cosim.sync.Run`` (``backend``, ``workers``, ``realtime``,
    ``progress``, ...). Returns the run's ``RunResult`` (its ``summary``,
    ``stop_reason``, ``out_dir``, ``error``)."""
    if _starting_worker():
        raise GuardMissing(
            "cosim.run() was called while a worker process was starting: cosim's workers "
            "import the calling script again, so keep the call under "
            "`if __name__ == \"__main__\":` (see examples/run_from_python.py)")
    return prepare_run(scenario, out, **options).run()


def prepare_run(scenario: str | Path | Scenario, out: str | Path | None = None, *,
                duration_s: float | None = None, overwrite: bool = False,
                mavlink_url: str | None = None, signing_key_file: str | None = None,
                signing_key_env: str | None = None, signing_link_id: int = 0,
                external_controller: bool = False, view: str | None = None,
                record_view: str | Path | None = None, view_rate_hz: float = 10.0,
                video: Sequence[str] = (), video_allow_remote: bool = False,
                backend: str = "process", backend_options: dict[str, Any] | None = None,
                names: dict[str, str] | None = None, **run_options: Any) -> Run:
    """The run of ``scenario`` into ``out``, ready to ``run()``; every problem
    with the options (a folder that holds a run, a bad MAVLink URL or key, an
    outside controller without a link, a backend option the backend does not
    take) is a ``ConfigError`` before anything is built.

    ``mavlink_url`` overrides the scenario's link (keeping its stream rates);
    ``signing_key_file`` / ``signing_key_env`` sign it; ``external_controller``
    leaves the scenario's controller (a section's, e.g. ``swarm:``) to
    another process (``cosim swarm``) kept in lockstep over the link;
    ``view`` ("spawn" or a viewer's URL) and ``record_view`` (an .rrd file)
    add the live 3-D view; ``video`` streams cameras (``SYSID[:CAM]=udp://HOST:PORT``).
    ``run_options`` go to ``cosim.sync.Run`` (``workers``, ``realtime``,
    ``progress``, ``step_timeout_s``, ``extra_participants``). ``names``: how
    the caller spells the options in its messages (the CLI's flags;
    default these keyword names)."""
    from cosim.scenario import load_scenario
    from cosim.sync import Run
    from cosim.sync.participants import has_controller

    n = {**PYTHON_NAMES, **(names or {})}
    scn = scenario if not isinstance(scenario, (str, Path)) else load_scenario(scenario)
    if duration_s is not None:
        scn = scn.with_duration(duration_s)
    folder = Path(out) if out is not None else Path("runs") / (
        f"{scn.folder_name}-{time.strftime('%Y%m%d-%H%M%S')}")
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{n['out']} {folder}: exists and is not a folder")
    if ((folder / "summary.json").exists() or (folder / "events.jsonl").exists()) \
            and not overwrite:
        raise ConfigError(f"{folder} already holds a run; choose another {n['out']} or pass "
                          f"{n['overwrite']}")  # the run clears it: never mixed with the new one
    mav_cfg = _mavlink(scn, mavlink_url, signing_key_file, signing_key_env, signing_link_id, n)
    if external_controller:
        from cosim.core.section import scenario_sections
        from cosim.mavlink import CONTROLLER_SYSID

        if not has_controller(scn):  # the part an outside controller runs
            kinds = ", ".join(f"{k}:" for k, sec in scenario_sections().items() if sec.controller)
            raise ConfigError(f"{n['external_controller']}: {scn.path} has no controller "
                              f"section ({kinds}) for an outside controller to run")
        if mav_cfg is None:
            raise ConfigError(f"{n['external_controller']} needs a network link: pass "
                              f"{n['mavlink_url']} URL (e.g. udpin:127.0.0.1:14560, where the "
                              f"controller connects)")
        if mav_cfg.signing:
            raise ConfigError(f"{n['external_controller']} with MAVLink signing: cosim swarm "
                              "--connect does not sign its messages yet, so the lockstep "
                              "would wait for answers it drops; run without signing on a "
                              "loopback link")
        mav_cfg = dataclasses.replace(mav_cfg, lockstep_sysid=CONTROLLER_SYSID)
    extra = list(run_options.pop("extra_participants", ()))
    if view is not None or record_view is not None:
        from cosim.sync.view import ViewParticipant

        extra.append(ViewParticipant(Path(record_view) if record_view else None, view,
                                     view_rate_hz))
    if video:
        from cosim.renderer.stream import VideoParticipant, parse_target

        extra.append(VideoParticipant([parse_target(t, video_allow_remote) for t in video],
                                      scn))
    return Run(scn, folder, backend=backend, mavlink=mav_cfg,
               external_controller=external_controller, extra_participants=extra,
               backend_options=_backend_options(backend, backend_options or {}),
               **run_options)


def _mavlink(scn: Scenario, url: str | None, key_file: str | None, key_env: str | None,
             link_id: int, n: dict[str, str]) -> Any:
    """The run's MAVLink config when the options change the scenario's (a URL,
    signing), else None (the run takes the scenario's own)."""
    from cosim.mavlink import MavlinkConfig, load_signing_key
    from cosim.mavlink.link import LinkUrl

    cfg = None
    if url:  # overrides the scenario's URL, keeps its stream rates
        LinkUrl.parse(url)  # a bad URL is a usage error before anything is built
        cfg = dataclasses.replace(MavlinkConfig.of_scenario(
            scn.mavlink, [v.id for v in scn.vehicles]) or MavlinkConfig(), url=url)
    if key_file or key_env:
        if cfg is None and scn.mavlink is None:
            raise ConfigError(f"{n['signing']} needs MAVLink: pass {n['mavlink_url']} or give "
                              f"the scenario a mavlink: section")
        cfg = cfg or MavlinkConfig.of_scenario(scn.mavlink, [v.id for v in scn.vehicles])
        assert cfg is not None
        cfg = dataclasses.replace(cfg, signing_key_file=key_file, signing_key_env=key_env,
                                  signing_link_id=link_id)
        load_signing_key(cfg)  # a missing or bad key is a usage error before the build
    return cfg


def _backend_options(backend: str, opts: dict[str, Any]) -> dict[str, Any]:
    """The backend's own options (a cluster's address), for it to take or
    refuse; a refusal, or a backend that cannot run here, is a usage error
    before anything is built."""
    from cosim.fdm_pool import backends, get_backend

    get_backend(backend).check()  # a library it needs, missing: said before anything runs
    unknown = sorted(set(opts) - set(get_backend(backend).options))
    if unknown:
        takers = [b.name for b in backends().values() if unknown[0] in b.options]
        raise ConfigError(f"--{unknown[0].replace('_', '-')}: the {backend} backend does "
                          f"not take it; backends that do: " + (", ".join(takers) or "none"))
    return dict(opts)
