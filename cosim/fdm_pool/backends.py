"""Pool backends by name: the built-in ones and any a package registers.

A backend is a ``Pool`` subclass (or any callable with its constructor's
signature) built as ``factory(specs, dt_s, channels, workers=None)``. cosim
ships ``inline`` (every vehicle in the calling process: the reference) and
``process`` (shards in worker processes, the default). Another package adds
one without touching cosim, in its ``pyproject.toml``::

    [project.entry-points."cosim.backends"]
    mybackend = "mypackage.pools:MyPool"

after which ``cosim run --backend mybackend`` and ``cosim bench --backend
mybackend`` use it, and ``tests/fdm_pool/test_conformance.py`` can check it
(``COSIM_CONFORMANCE_BACKENDS=mybackend python -m pytest
tests/fdm_pool/test_conformance.py``): bit-identical states against
``inline``, statuses, faults and misuse as the ``Pool`` contract says.

A backend may take options beyond these, as keyword arguments of its
factory (``ray``: ``address``, the cluster to join, and ``strict``, stop
rather than recover when a machine is lost). ``cosim run --address`` and
``--strict`` pass them on to whichever backend runs; one that does not take
an option it is given refuses it with a ``ConfigError`` naming the ones it
takes.

Nothing outside a backend asks which backend runs: the CLI lists them from
here, and each says how many workers it uses by default
(``Pool.default_workers``).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from cosim.core import plugins
from cosim.core.plugins import load_plugins, plugin_names
from cosim.core.state import VehicleSpec
from cosim.errors import ConfigError
from cosim.fdm_pool.base import Pool

#: the default backend of ``cosim run``
DEFAULT = plugins.DEFAULT_BACKEND


@dataclass(frozen=True)
class Backend:
    """A registered backend: ``factory(specs, dt_s, channels, workers=None) -> Pool``."""

    name: str
    factory: Callable[..., Pool]
    source: str  # "cosim" or the distribution that registered it

    @property
    def description(self) -> str:
        doc = getattr(self.factory, "__doc__", None) or ""
        return doc.strip().splitlines()[0] if doc.strip() else ""

    def default_workers(self) -> int:
        """The workers it uses when none are asked for."""
        fn = getattr(self.factory, "default_workers", None)
        return int(fn()) if callable(fn) else 1

    def check(self) -> None:
        """``ConfigError`` if it cannot run here (``Pool.available``)."""
        fn = getattr(self.factory, "available", None)
        if callable(fn):
            fn()

    @property
    def options(self) -> tuple[str, ...]:
        """The keyword options its factory takes beyond the common arguments."""
        try:
            params = inspect.signature(self.factory).parameters
        except (TypeError, ValueError):
            return ()
        return tuple(name for name, p in params.items()
                     if name not in _COMMON and p.kind in (p.KEYWORD_ONLY,
                                                           p.POSITIONAL_OR_KEYWORD))

    def make(self, specs: Sequence[VehicleSpec], dt_s: float, channels: Sequence[str] = (),
             workers: int | None = None, **options: Any) -> Pool:
        """Build the pool; ``options``: the backend's own (``options``), refused
        with a ``ConfigError`` if it does not take them."""
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            takes = ", ".join(self.options) or "none"
            raise ConfigError(f"the {self.name} backend takes no option "
                              f"{', '.join(repr(u) for u in unknown)} (its options: {takes})")
        return self.factory(specs, dt_s, channels, workers=workers, **options)


#: the arguments every backend's factory takes
_COMMON = ("self", "specs", "dt_s", "channels", "workers")


@lru_cache(maxsize=1)
def backends() -> dict[str, Backend]:
    """Every backend by name: the built-in ones, then the registered ones."""
    return {name: Backend(name, p.obj, p.source)
            for name, p in load_plugins(plugins.BACKENDS, plugins.BUILTIN_BACKENDS).items()}


def backend_names() -> list[str]:
    """The names of every backend, without loading any (for ``--help``)."""
    return plugin_names(plugins.BACKENDS, plugins.BUILTIN_BACKENDS)


def get_backend(name: str) -> Backend:
    """The backend called ``name``; ``ConfigError`` listing the others if none is."""
    return plugins.pick(plugins.BACKENDS, backends(), name, ("backend", "backends"))
