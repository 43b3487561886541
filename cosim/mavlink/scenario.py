"""The ``mavlink:`` section of a scenario file: its parser and which vehicles
it puts on MAVLink.

The scenario loader calls these with its own problem reporting (``report``
a problem at a path, a ``reader`` of one mapping as sections get them,
``cosim.core.section.Reader``, ``select`` vehicle rows by 'all', ids and
patterns), so that this part needs nothing of the loader.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from fnmatch import fnmatchcase
from typing import Any

from cosim.core.section import P, Reader
from cosim.errors import ConfigError
from cosim.mavlink.link import DEFAULT_URL, LinkUrl
from cosim.mavlink.vehicle import check_rates

#: the keys of the section
KEYS = ("url", "rates_hz", "vehicles")


def parse_mavlink(node: Any, report: Callable[[P, str], None],
                  reader: Callable[[Any, P, tuple[str, ...]], Reader]
                  ) -> dict[str, Any] | None:
    """``mavlink: true`` or ``mavlink: {url: udpout:HOST:PORT, rates_hz: {MSG: Hz},
    vehicles: PATTERNS}`` -> ``{"url", "rates_hz"[, "vehicles"]}`` (None:
    ``false``); the vehicles are checked by ``check_vehicles`` once known."""
    if node is False:
        return None
    if node is True:
        node = {}
    r = reader(node, ("mavlink",), KEYS)
    url = r.string("url", DEFAULT_URL)
    if url is not None:
        try:
            LinkUrl.parse(url)
        except ConfigError as e:
            report(("mavlink", "url"), str(e))
    rates = r.d.get("rates_hz", {})
    if not isinstance(rates, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in rates.values()):
        report(("mavlink", "rates_hz"), "expected a mapping of message name: Hz")
        rates = {}
    for problem in check_rates(rates):
        report(("mavlink", "rates_hz"), problem)
    out: dict[str, Any] = {"url": url or DEFAULT_URL,
                           "rates_hz": {str(k): float(v) for k, v in rates.items()}}
    if r.has("vehicles"):
        out["vehicles"] = r.d["vehicles"]
    return out


def check_vehicles(section: dict[str, Any], select: Callable[[Any, P], list[int]]
                   ) -> None:
    """``mavlink.vehicles``: which vehicles are on MAVLink ('all', an id, a
    pattern or a list of them; default all), checked by ``select`` against
    the scenario's vehicles. Kept as patterns, resolved to rows by
    ``mavlink_rows``."""
    sel = section["vehicles"]
    select(sel, ("mavlink", "vehicles"))
    section["vehicles"] = sel if isinstance(sel, list) else [sel]


def mavlink_rows(section: Mapping[str, Any] | None, ids: Sequence[str]
                 ) -> tuple[int, ...] | None:
    """The state rows of the vehicles a scenario's ``mavlink:`` section puts
    on MAVLink (its ``vehicles`` patterns); None: every vehicle."""
    pats = (section or {}).get("vehicles")
    if pats is None or pats == ["all"]:
        return None
    return tuple(i for i, v in enumerate(ids) if any(fnmatchcase(v, p) for p in pats))
