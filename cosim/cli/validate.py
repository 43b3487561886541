"""``cosim validate``: every problem of every file, at every sweep combination;
``--deep`` also builds and trims every vehicle."""

from __future__ import annotations

import argparse
import logging
import re
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.cli.common import EXIT_OK, EXIT_USAGE
from cosim.core.section import CliCommand
from cosim.errors import ConfigError, CosimError

if TYPE_CHECKING:
    from cosim.scenario import Scenario


log = logging.getLogger("cosim")

def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO")
    p.add_argument("--deep", action="store_true",
                   help="also build and trim every vehicle (as a run would), so a vehicle "
                        "JSBSim cannot trim is found before a long run starts")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes for --deep (default: one per core)")


def run(a: argparse.Namespace) -> int:
    if a.workers is not None and a.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {a.workers}")
    bad = 0
    for f in a.scenarios:
        try:
            scn, combos, built = _validate_file(f, a.deep, a.workers)
        except ConfigError as e:
            bad += 1
            print(e, file=sys.stderr)
            continue
        except (CosimError, OSError) as e:  # e.g. a model JSBSim cannot load
            bad += 1
            print(f"{f}: {e}", file=sys.stderr)
            continue
        deep = ""
        if a.deep:
            deep = ", every vehicle built and trimmed" if combos == 1 else \
                f", the vehicles of {built} distinct combination(s) built and trimmed"
        sweep = f"; all {combos} sweep combinations" if combos > 1 else ""
        print(f"{f}: ok ({len(scn.vehicles)} vehicles, {scn.duration_s:g} s, "
              f"{scn.rates.physics_hz:g}/{scn.rates.control_hz:g}/{scn.rates.log_hz:g} Hz"
              f"{sweep}{deep})")
    return EXIT_USAGE if bad else EXIT_OK


def _validate_file(f: str, deep: bool, workers: int | None) -> tuple[Scenario, int, int]:
    """Check a scenario file, every combination of its sweep (values the first
    combination does not have can fail: a speed beyond the model's envelope);
    with ``deep``, build the vehicles of each distinct combination. Returns
    the first combination's scenario, the combinations checked and built."""
    from cosim.scenario import load_scenario
    from cosim.scenario.memo import Memo
    from cosim.scenario.schema import check_scenario
    from cosim.sweep.spec import read_sweep

    memo = Memo()  # the file parsed once; parts the same in two combinations checked once
    data, lines, _, _ = memo.parsed(memo.read(Path(f)), f)
    spec = read_sweep(f, (data, lines))
    points: list[dict[str, Any] | None] = list(spec.points()) if spec.values else [None]
    found: dict[str, list[int]] = {}  # problem -> the combinations that have it
    more = 0  # problems counted beyond those kept
    first: Scenario | None = None
    seen: set[tuple[Any, ...]] = set()
    built = 0
    t0 = last = time.monotonic()
    for done, point in enumerate(points):
        if time.monotonic() - last >= 5.0:
            last = time.monotonic()
            log.info("%s: %d of %d sweep combinations checked (%.0f s)", f, done, len(points),
                     last - t0)
        problems: list[str] = []
        try:
            if first is not None and not deep:  # only the problems matter
                check_scenario(f, sweep_point=point, memo=memo)
                continue
            scn = load_scenario(f, sweep_point=point, memo=memo)
            if first is None:
                first = scn
            key = tuple((v.model, v.vehicle_class, v.alt_msl_m, v.airspeed_mps, v.trim,
                         v.initial_props) for v in scn.vehicles)
            if deep and key not in seen:
                seen.add(key)
                built += 1
                _build_all(scn, f, workers)
        except ConfigError as e:
            problems, more = e.problems, more + e.more
        except (CosimError, OSError) as e:
            problems = [f"{f}: {e}"]
        for m in problems:
            where = found.setdefault(m, [])
            if not where or where[-1] != done:
                where.append(done)
    if found:
        def line(problem: str) -> int:  # in file order, as one combination's are
            m = re.match(rf"{re.escape(f)}:(\d+): ", problem)
            return int(m.group(1)) if m else 0

        raise ConfigError([_in_combinations(m, [points[i] for i in rows], len(points),
                                            spec.values, spec.swept)
                           for m, rows in sorted(found.items(), key=lambda kv: line(kv[0]))],
                          more)
    assert first is not None
    return first, len(points), built


def _in_combinations(problem: str, where: list[dict[str, Any] | None], total: int,
                     values: dict[str, tuple[Any, ...]], swept: Sequence[str]) -> str:
    """A problem found in the sweep combinations ``where`` (of ``total``; the
    sweep's ``values``), said once: ``sweep combinations speed_kt=400,
    alt_agl_m=any (12 of 36): ...``; combinations that do not make such a
    product are named by the first and counted."""
    from cosim.scenario.placeholders import format_value

    points = [p for p in where if p is not None]
    if total == 1 or not points:  # no sweep
        return problem
    if len(points) == total:
        return f"every sweep combination: {problem}"
    seen = {n: list(dict.fromkeys(p[n] for p in points)) for n in swept}

    def named(n: str, vals: list[Any]) -> str:
        if len(vals) > 1 and len(vals) == len(values[n]):
            return f"{n}=any"
        return f"{n}={'|'.join(format_value(v) for v in vals)}"

    product = 1
    for vals in seen.values():
        product *= len(vals)
    if len(points) == 1:
        return f"sweep combination {', '.join(named(n, v) for n, v in seen.items())}: {problem}"
    if product == len(points):  # every combination of the values seen
        return (f"sweep combinations {', '.join(named(n, v) for n, v in seen.items())} "
                f"({len(points)} of {total}): {problem}")
    first = ", ".join(named(n, [points[0][n]]) for n in swept)
    return (f"sweep combination {first} (and {len(points) - 1} other "
            f"combination{'s' * (len(points) > 2)}): {problem}")


def _build_all(scn: Scenario, fname: str, workers: int | None) -> None:
    """Build and trim every vehicle of ``scn`` as a run would (process
    backend); the vehicles that fail become a ``ConfigError`` with the line of
    each one's scenario entry."""
    from cosim.errors import BuildError
    from cosim.fdm_pool import make_pool
    from cosim.scenario.yaml_lines import format_path

    try:
        with make_pool(scn.vehicles, scn.rates.dt_s, scn.channels, "process", workers):
            pass
    except BuildError as e:
        index = {v.id: i for i, v in enumerate(scn.vehicles)}
        paths, lines = scn.extra.get("vehicle_paths", []), scn.extra.get("vehicle_lines", [])
        problems = []
        for vid, msg in e.failures:
            i = index.get(vid)
            where = f"{lines[i]}: {format_path(paths[i])}" if i is not None and i < len(
                lines) else "1: vehicles"
            problems.append(f"{fname}:{where}: {msg}")
        raise ConfigError(problems) from None


COMMAND = CliCommand(
    "validate",
    "check scenario files and report every problem",
    add_arguments, run, rank=20)
