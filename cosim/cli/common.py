"""What the CLI's commands share: exit codes, the parser that reports usage
errors as exit 2, argument types, loading a scenario, the backend names."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cosim.scenario import Scenario

from cosim.core.args import (  # noqa: F401 - the commands import them from here
    EXIT_FAIL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    altitudes,
    positive_float,
    positive_int_list,
)
from cosim.errors import ConfigError


class UsageError(Exception):
    """A command line the parser refuses (printed, exit 2)."""


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: error: {message}")


def load_scenario(path: str) -> Scenario:
    from cosim.scenario import load_scenario as load  # imported here: a fast --help

    return load(path)


def add_coordinating_driver(p: argparse.ArgumentParser) -> None:
    p.add_argument("--coordinating-driver", action="store_true",
                   help="the driver steps no aircraft and only coordinates the workers "
                        "(default: with two workers or more it steps one worker's share "
                        "itself)")


def driver_options(backend: str, coordinating: bool) -> dict[str, Any]:
    """The backend option ``--coordinating-driver`` stands for
    (``driver_steps=False``), refused with the backends that take it when
    ``backend`` does not."""
    if not coordinating:
        return {}
    from cosim.fdm_pool import backends, get_backend

    if "driver_steps" not in get_backend(backend).options:
        takers = [b.name for b in backends().values() if "driver_steps" in b.options]
        raise ConfigError(f"--coordinating-driver: the {backend} backend has no driver share "
                          f"to give up; backends that do: {', '.join(takers) or 'none'}")
    return {"driver_steps": False}


def backend_names() -> tuple[list[str], str, str]:
    """(every backend's name, the default, what they do) for ``--backend``;
    registered ones included, nothing loaded (a fast --help)."""
    from cosim.core.plugins import BACKENDS, BUILTIN_BACKENDS, DEFAULT_BACKEND, plugin_names

    return (plugin_names(BACKENDS, BUILTIN_BACKENDS), DEFAULT_BACKEND,
            "inline runs every vehicle in this process (the reference), process shards them "
            "over worker processes; packages may register more")
