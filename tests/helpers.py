"""Helpers several test folders share (import as ``tests.helpers``)."""

from __future__ import annotations

import contextlib
import importlib
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any


def install_out_of_tree(folder: Path, name: str, modules: dict[str, str],
                        entry_points: dict[str, dict[str, str]]) -> Path:
    """Build a small package ``name`` from ``modules`` (module name -> source)
    with ``entry_points`` (group -> name -> "module:attr") and install it with
    pip into ``folder/site`` (not into this environment); returns that folder,
    to put on ``PYTHONPATH`` (or ``sys.path``). Offline: no build isolation."""
    src = folder / "src"
    src.mkdir(parents=True)
    eps = "".join(f'\n[project.entry-points."{group}"]\n'
                  + "".join(f'{k} = "{v}"\n' for k, v in entries.items())
                  for group, entries in entry_points.items())
    (src / "pyproject.toml").write_text(textwrap.dedent(f"""
        [build-system]
        requires = ["setuptools>=61"]
        build-backend = "setuptools.build_meta"

        [project]
        name = "{name}"
        version = "0.1"

        [tool.setuptools]
        py-modules = {sorted(modules)!r}
    """).replace("'", '"') + eps)
    for mod, code in modules.items():
        (src / f"{mod}.py").write_text(textwrap.dedent(code))
    site = folder / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                        "--no-build-isolation", "--no-index", "--target", str(site), str(src)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return site


#: the backends that run on a cluster, and the fixture that starts it for a
#: test (a test on one is in the integration tier: tests/conftest.py)
CLUSTER_BACKENDS = {"ray": "ray_cluster"}


@contextlib.contextmanager
def plugged_in(site: Path, module: str, forget: Callable[[], None]) -> Iterator[Path]:
    """``install_out_of_tree``'s folder on ``sys.path`` (spawned workers
    inherit it) while inside, its ``module`` forgotten after; ``forget``
    clears the cached plug-in table it joins, on the way in and out."""
    sys.path.insert(0, str(site))
    importlib.invalidate_caches()
    forget()
    try:
        yield site
    finally:
        sys.path.remove(str(site))
        sys.modules.pop(module, None)
        importlib.invalidate_caches()
        forget()


def backend_ready(request: Any, name: str) -> None:
    """Whatever backend ``name`` needs to run, started for the test (``ray``:
    the session's cluster)."""
    if name in CLUSTER_BACKENDS:
        request.getfixturevalue(CLUSTER_BACKENDS[name])


def same_states(a: Any, b: Any) -> bool:
    """Two runs' states tables hold the same rows, bit for bit. Their layout is
    not compared: the writer flushes parts by the wall clock (nothing is lost
    on a crash), so how many chunks the rows arrive in, and each chunk's
    dictionary of vehicle ids and command texts, depend on the machine's
    speed, never the values."""
    import pyarrow as pa

    def plain(t: Any) -> Any:
        cols = [c.cast(c.type.value_type) if pa.types.is_dictionary(c.type) else c
                for c in t.columns]
        return pa.table(cols, names=t.column_names).combine_chunks()

    return bool(plain(a).equals(plain(b)))


def finished_run(text: str, folder: Path) -> Path:
    """The run folder of scenario ``text`` run to its end (inline) in
    ``folder/run`` (the scenario written as ``folder/s.yaml``)."""
    from cosim.scenario import parse_scenario
    from cosim.sync import run_scenario

    res = run_scenario(parse_scenario(text, str(folder / "s.yaml")), folder / "run",
                       backend="inline")
    assert res.stop_reason == "completed", res.error
    return folder / "run"


def run_by_vehicle(text: str, folder: Path, backend: str = "inline", workers: int | None = None,
                   check_properties: bool = False
                   ) -> tuple[dict[str, dict[str, Any]], list[dict[str, Any]]]:
    """Scenario ``text`` run to its end in ``folder/run``: each vehicle's
    logged columns (arrays) by name, and the run's events."""
    import json

    import numpy as np

    from cosim.logs import read_states
    from cosim.scenario import parse_scenario
    from cosim.sync import run_scenario

    scn = parse_scenario(text, str(folder / "s.yaml"), check_properties=check_properties)
    res = run_scenario(scn, folder / "run", backend=backend, workers=workers)
    assert res.stop_reason == "completed", res.error
    t = read_states(folder / "run")
    who = np.array(t["vehicle"].to_pylist())
    cols = {v: {k: np.asarray(t[k].to_pylist())[who == v] for k in t.column_names
                if k not in ("vehicle", "command")} for v in sorted(set(who))}
    lines = (folder / "run" / "events.jsonl").read_text().splitlines()
    return cols, [json.loads(x) for x in lines]
