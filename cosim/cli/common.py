"""What the CLI's commands share: exit codes, the parser that reports usage
errors as exit 2, argument types, loading a scenario, the backend names."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

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


class UsageError(Exception):
    """A command line the parser refuses (printed, exit 2)."""


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: error: {message}")


def load_scenario(path: str) -> Scenario:
    from cosim.scenario import load_scenario as load  # imported here: a fast --help

    return load(path)


def backend_names() -> tuple[list[str], str, str]:
    """(every backend's name, the default, what they do) for ``--backend``;
    registered ones included, nothing loaded (a fast --help)."""
    from cosim.core.plugins import BACKENDS, BUILTIN_BACKENDS, DEFAULT_BACKEND, plugin_names

    return (plugin_names(BACKENDS, BUILTIN_BACKENDS), DEFAULT_BACKEND,
            "inline runs every vehicle in this process (the reference), process shards them "
            "over worker processes; packages may register more")
