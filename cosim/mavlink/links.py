"""More vehicles than one MAVLink link can carry: one endpoint per 240.

System ids are 8 bits and ground stations keep 251..255 for themselves, so
one link (``MavlinkEndpoint``) carries at most ``MAX_VEHICLES_PER_LINK``
(240) vehicles. A run with more gets one link per 240 vehicles, in vehicle
order, each with system ids 1..240 on its own port (only the vehicles the
scenario's ``mavlink.vehicles`` selects, when it does):

- ``udpout:HOST:PORT``: link k sends to ``PORT + k`` (point one ground
  station, or one MAVProxy ``--master``, at each port);
- ``udpin:HOST:PORT``: link k listens on ``PORT + k`` (``PORT`` 0: each
  link an ephemeral port, see ``local_addresses``);
- in-process only (``url`` None): no ports; in-process clients tell the
  links apart by the ``link`` index ``subscribe`` callbacks receive and
  ``inject`` takes.

``MavlinkLinks`` drives them together with the endpoint's interface. With
signing on, the links share one replay protection (``SharedSigning``): a
signed packet accepted on one link is a replay on every other, whatever its
link id says.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.state import VehicleSpec
from cosim.errors import ConfigError
from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.config import MavlinkConfig, load_signing_key
from cosim.mavlink.endpoint import MAX_VEHICLES_PER_LINK, MavlinkEndpoint
from cosim.mavlink.link import LinkUrl
from cosim.mavlink.router import VehicleCommand
from cosim.mavlink.signing import SharedSigning
from cosim.mavlink.vehicle import MavClass, MavVehicleSpec, mav_specs


def link_specs(vehicles: Sequence[VehicleSpec], classes: Callable[[str], MavClass],
               rows: Sequence[int] | None = None) -> list[list[MavVehicleSpec]]:
    """The MAVLink identities of a run's vehicles (those of ``rows``; None:
    all; ``classes``: what each class hands down, see ``mav_specs``), one list
    per link: in vehicle order, system ids 1..240 on each link."""
    chosen = list(range(len(vehicles))) if rows is None else sorted(rows)
    out = []
    for a in range(0, len(chosen), MAX_VEHICLES_PER_LINK):
        part = chosen[a:a + MAX_VEHICLES_PER_LINK]
        out.append(mav_specs([vehicles[r] for r in part], classes, first_sysid=1, rows=part))
    return out


def link_urls(url: str | None, n: int) -> list[str | None]:
    """The URL of each of ``n`` links (see the module docstring)."""
    if url is None:
        return [None] * n
    u = LinkUrl.parse(url)
    if n > 1 and u.port and u.port + n - 1 > 65535:
        raise ConfigError(f"mavlink {url}: {n} links need ports {u.port}..{u.port + n - 1}")
    return [str(dataclasses.replace(u, port=u.port + k if u.port else 0)) for k in range(n)]


class MavlinkLinks:
    """Every vehicle of a run on as many links as it takes (see the module
    docstring); the interface of ``MavlinkEndpoint``, with the link index
    where it matters. ``classes``: what each vehicle class hands down (its
    personality and safety rule, see ``mav_specs``)."""

    def __init__(self, vehicles: Sequence[VehicleSpec], classes: Callable[[str], MavClass],
                 physics_hz: float, config: MavlinkConfig, tlog_dir: str | Path | None = None,
                 clock_anchor_unix_us: int | None = None) -> None:
        self.specs = link_specs(vehicles, classes, config.rows)
        if not self.specs:
            raise ConfigError("mavlink: vehicles selects no vehicle")
        #: the link of each vehicle on MAVLink, by state row
        self.link_of_row = {v.row: k for k, specs in enumerate(self.specs) for v in specs}
        n = len(self.specs)
        if n > 1 and config.lockstep_sysid is not None:
            raise ConfigError(f"mavlink: an outside controller in lockstep drives one link "
                              f"(at most {MAX_VEHICLES_PER_LINK} vehicles); this run has "
                              f"{len(vehicles)}: run the controller in-process")
        self.config = config
        self.urls = link_urls(config.url, n)
        self.endpoints: list[MavlinkEndpoint] = []
        key = load_signing_key(config)
        #: the links' one replay protection (None: signing off)
        self.signing = None if key is None else SharedSigning(key, config.signing_state_dir)
        try:
            for specs, url in zip(self.specs, self.urls):
                self.endpoints.append(MavlinkEndpoint(
                    specs, physics_hz, dataclasses.replace(config, url=url), tlog_dir=tlog_dir,
                    clock_anchor_unix_us=clock_anchor_unix_us, signing=self.signing))
                if clock_anchor_unix_us is None:  # every link on the same clock
                    clock_anchor_unix_us = self.endpoints[0].clock.anchor_unix_us
        except BaseException:
            self.close()
            raise

    @property
    def local_addresses(self) -> list[tuple[str, int]]:
        return [e.local_address for e in self.endpoints]

    def __enter__(self) -> MavlinkLinks:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        for e in self.endpoints:
            e.close()
        if self.signing is not None:
            self.signing.close()

    def inject(self, message: mav.Message, link: int = 0) -> None:
        """Queue an in-process message for the vehicles of ``link``."""
        self.endpoints[link].inject(message)

    def local_command(self, row: int, command: Command) -> Command:
        """See ``MavlinkEndpoint.local_command`` (a vehicle not on MAVLink:
        the command unchanged)."""
        k = self.link_of_row.get(row)
        return command if k is None else self.endpoints[k].local_command(row, command)

    def load_mission(self, row: int, items: Sequence[Any], fly: bool = True) -> bool:
        """See ``MavlinkEndpoint.load_mission``; False: the vehicle at ``row``
        is not on MAVLink."""
        k = self.link_of_row.get(row)
        if k is None:
            return False
        self.endpoints[k].load_mission(row, items, fly)
        return True

    def subscribe(self, callback: Callable[[mav.Message, int], None]) -> None:
        """``callback(message, link)`` for every packet any vehicle sends."""
        for k, e in enumerate(self.endpoints):
            e.subscribe(_tagged(callback, k))

    def exchange(self, tick: int, states: np.ndarray) -> list[VehicleCommand]:
        commands = self.receive(tick, states)
        self.send_telemetry(tick)
        return commands

    def receive(self, tick: int, states: np.ndarray) -> list[VehicleCommand]:
        out: list[VehicleCommand] = []
        for e in self.endpoints:
            out += e.receive(tick, states)
        return out

    def send_telemetry(self, tick: int) -> None:
        for e in self.endpoints:
            e.send_telemetry(tick)

    def set_video(self, streams: Mapping[int, Any]) -> None:
        """See ``MavlinkEndpoint.set_video`` (system ids of the first link)."""
        self.endpoints[0].set_video(streams)

    def drain_events(self) -> list[tuple[int, str, dict[str, Any]]]:
        """See ``MavlinkEndpoint.drain_events``."""
        return [ev for e in self.endpoints for ev in e.drain_events()]

    def counters(self) -> dict[str, Any]:
        """Every counter summed over the links (``links``: how many)."""
        total: Counter[str] = Counter()
        for e in self.endpoints:
            total.update(e.counters())
        out: dict[str, Any] = dict(sorted(total.items()))
        out["links"] = len(self.endpoints)
        return out


def _tagged(callback: Callable[[mav.Message, int], None], link: int
            ) -> Callable[[mav.Message], None]:
    def deliver(m: mav.Message) -> None:
        callback(m, link)
    return deliver
