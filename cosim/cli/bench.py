"""``cosim bench``: the pool's throughput against the serial loop and the
no-communication ceiling (``cosim.bench``)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from cosim.cli.common import (
    EXIT_OK,
    add_coordinating_driver,
    backend_names,
    driver_options,
    positive_float,
    positive_int_list,
)
from cosim.core.section import CliCommand
from cosim.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    names, DEFAULT_BACKEND, backend_help = backend_names()  # noqa: N806
    p.add_argument("--vehicles", type=positive_int_list, default=[1, 16, 128, 512, 1024],
                   metavar="N,N,...",
                   help="fleet sizes to measure, one row each (default 1,16,128,512,1024)")
    p.add_argument("--model", default="c172p", metavar="MODEL",
                   help="the aircraft model, as in a scenario (default c172p; `cosim models` "
                        "lists them)")
    p.add_argument("--backend", choices=names, default=DEFAULT_BACKEND,
                   help=f"{backend_help} (default {DEFAULT_BACKEND})")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the pool (default: one per core)")
    p.add_argument("--seconds", type=positive_float, default=5.0, metavar="S",
                   help="simulated seconds per measured segment (default 5)")
    p.add_argument("--repeat", type=int, default=3, metavar="R",
                   help="segments per configuration; the best is reported (default 3)")
    p.add_argument("--physics-hz", type=positive_float, default=120.0, metavar="HZ",
                   help="JSBSim steps per simulated second (default 120)")
    p.add_argument("--control-hz", type=positive_float, default=30.0, metavar="HZ",
                   help="exchanges (setpoints in, states out) per simulated second; must "
                        "divide --physics-hz (default 30)")
    p.add_argument("--no-baselines", action="store_true",
                   help="skip the serial and no-communication ceiling measurements")
    p.add_argument("--json", metavar="FILE", help="write the results as JSON")
    p.add_argument("--class", dest="vehicle_class", metavar="CLASS",
                   help="fly the model as this vehicle class (e.g. fixed_wing_batched); "
                        "default: the model's own")
    p.add_argument("--plot", metavar="FILE.png",
                   help="draw the real-time factor and the efficiency against N")
    p.add_argument("--whole-run", action="store_true",
                   help="also fly each fleet as a whole run (guidance, logging) and report "
                        "its real-time factor and where its tick loop's time goes")
    p.add_argument("--log-hz", type=positive_float, default=10.0, metavar="HZ",
                   help="the whole run's logging rate (default 10)")
    p.add_argument("--gym", action="store_true",
                   help="also measure what an RL user would otherwise write: gymnasium's "
                        "AsyncVectorEnv, one aircraft per environment, at 16 and 64 aircraft "
                        "(needs the rl extra)")
    add_coordinating_driver(p)
    p.add_argument("--quick", action="store_true",
                   help="a look in under a minute: 1, 16 and 128 aircraft, 1 s, one round")


def run(a: argparse.Namespace) -> int:
    from cosim.bench.fleet import check_rates
    from cosim.bench.pool import run_bench

    if a.workers is not None and a.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {a.workers}")
    try:
        check_rates(a.physics_hz, a.control_hz)
    except ValueError as e:
        raise ConfigError(f"--physics-hz/--control-hz: {e}") from None
    for opt, path in (("--json", a.json), ("--plot", a.plot)):
        if not path:
            continue
        folder = Path(path).resolve().parent
        if not folder.is_dir():
            raise ConfigError(f"{opt} {path}: folder {folder} does not exist")
        if not os.access(folder, os.W_OK):
            raise ConfigError(f"{opt} {path}: folder {folder} is not writable")
        if Path(path).is_dir():
            raise ConfigError(f"{opt} {path}: is a folder")
    if a.vehicle_class is not None:
        from cosim.vehicles.registry import get_class

        get_class(a.vehicle_class)  # an unknown class: ConfigError naming the known ones
    if a.gym:
        from cosim.bench.gym import require_gymnasium

        require_gymnasium()  # not installed: a usage error before anything runs
    if a.quick:
        a.vehicles, a.seconds, a.repeat = [1, 16, 128], 1.0, 1
    run_bench(vehicles=a.vehicles, model=a.model, backend=a.backend, workers=a.workers,
              seconds=a.seconds, physics_hz=a.physics_hz, control_hz=a.control_hz,
              baselines=not a.no_baselines, repeat=max(1, a.repeat), json_path=a.json,
              vehicle_class=a.vehicle_class, plot_path=a.plot, whole=a.whole_run,
              log_hz=a.log_hz, gym=a.gym, options=driver_options(a.backend,
                                                                    a.coordinating_driver))
    return EXIT_OK


COMMAND = CliCommand(
    "bench",
    "measure pool throughput against the serial loop",
    add_arguments, run, rank=120, flies_aircraft=True,
    epilog="One row per fleet size; what each column means is printed under the table (and in "
           "benchmarks/README.md).")
