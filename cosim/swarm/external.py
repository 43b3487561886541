"""The swarm controller as a separate process over UDP (``cosim swarm
SCENARIO --connect udpout:HOST:PORT``), in lockstep with
``cosim run SCENARIO --mavlink udpin:HOST:PORT --external-controller``.

The same ``SwarmController`` as in-process, fed by a socket: say hello
(HEARTBEAT, repeated until the simulation answers), then for every datagram
decode the messages; telemetry goes to the controller; the simulation's
TIMESYNC request (``tc1 = 0`` from system 1, ``ts1`` = the exchange's
simulation time in ns) marks the end of tick T's telemetry: at a controller
step the commands for T are sent, then the answer (``tc1`` non-zero,
``ts1`` echoed) releases the next exchange, which handles the commands at
the same tick as in-process ``inject``. Results are bit-identical.

Metrics: this process has only telemetry, so the monitor runs on the
positions received (GLOBAL_POSITION_INT, 1e-7 deg / 1 mm), once per
exchange. It writes to ``--out DIR``: ``swarm.json`` (what the in-process
run puts in ``summary.json["swarm"]``), ``swarm_events.jsonl`` (phase and
separation events), ``swarm_commands.csv``, ``swarm_separation.csv`` and
``swarm.png``. The run
folder of the simulation has no swarm section or events in this mode.
"""

from __future__ import annotations

import json
import logging
import socket
import time
from pathlib import Path
from typing import Any

from cosim.errors import ConfigError, CosimError
from cosim.mavlink import adapter as mav
from cosim.mavlink.endpoint import CONTROLLER_SYSID
from cosim.mavlink.link import LinkUrl
from cosim.scenario import Scenario
from cosim.swarm.config import SwarmSpec
from cosim.swarm.controller import CONTROLLER_COMPID, SwarmController
from cosim.swarm.metrics import SwarmMonitor

log = logging.getLogger(__name__)

HELLO_EVERY_S = 0.5


class ControllerTimeout(CosimError):
    """The simulation never answered, or went silent mid-run."""


def _full(name: str, **fields: Any) -> dict[str, Any]:
    out = dict.fromkeys(mav.field_names(name), 0)
    out.update(fields)
    return out


class UdpController:
    """One socket to the simulation; ``run()`` until it ends."""

    def __init__(self, scenario: Scenario, url: str, out_dir: str | Path | None = None,
                 connect_timeout_s: float = 60.0, idle_timeout_s: float = 5.0) -> None:
        u = LinkUrl.parse(url)
        if u.mode != "udpout":
            raise ConfigError(f"--connect {url}: expected udpout:HOST:PORT (where the "
                              f"simulation's --mavlink udpin:HOST:PORT listens)")
        spec = scenario.sections.get("swarm")
        if not isinstance(spec, SwarmSpec):
            raise ConfigError(f"{scenario.path}: no swarm: section to run")
        self.scn = scenario
        self.addr = (socket.gethostbyname(u.host), u.port)
        self.out = Path(out_dir) if out_dir is not None else None
        self.connect_timeout_s = connect_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.hz = scenario.rates.physics_hz
        self.ctl = SwarmController(spec, scenario.vehicles, scenario.origin.frame, self.hz)
        self.mon = SwarmMonitor(spec, self.ctl.ids, [g.idx for g in self.ctl.groups], self.hz)
        self.packer = mav.Packer(system_id=CONTROLLER_SYSID, component_id=CONTROLLER_COMPID)
        self.decoder = mav.Decoder()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.sock.bind(("0.0.0.0" if u.host not in ("127.0.0.1", "localhost") else u.host, 0))
        self.events: list[dict[str, Any]] = []
        self.last_tick = -1
        self.exchanges = 0

    def _send(self, name: str, fields: dict[str, Any]) -> None:
        self.sock.sendto(self.packer.pack(name, **_full(name, **fields)), self.addr)

    def _hello(self) -> None:
        self._send("HEARTBEAT", {"type": mav.MAV_TYPE_GCS, "autopilot": 8,
                                 "mavlink_version": 3})

    def run(self) -> dict[str, Any]:
        """Control until the simulation ends (silence after the last exchange);
        the swarm summary."""
        total = self.scn.total_ticks
        last_exchange = total - self.scn.rates.control_every
        t0 = time.monotonic()
        spoke = False
        next_hello = 0.0
        try:
            while True:
                now = time.monotonic()
                if not spoke:
                    if now - t0 > self.connect_timeout_s:
                        raise ControllerTimeout(
                            f"cosim swarm: no answer from the simulation at "
                            f"{self.addr[0]}:{self.addr[1]} within "
                            f"{self.connect_timeout_s:g} s; is `cosim run ... --mavlink "
                            f"udpin:{self.addr[0]}:{self.addr[1]} --external-controller` "
                            f"running?")
                    if now >= next_hello:
                        self._hello()
                        next_hello = now + HELLO_EVERY_S
                    self.sock.settimeout(HELLO_EVERY_S)
                else:
                    self.sock.settimeout(self.idle_timeout_s)
                try:
                    data = self.sock.recv(65535)
                except TimeoutError:
                    if spoke:
                        log.info("simulation silent for %g s after tick %d: done",
                                 self.idle_timeout_s, self.last_tick)
                        break
                    continue
                spoke = True
                for m in self.decoder.decode(data):
                    if m.name == "TIMESYNC" and m.src_system == 1 and m.fields["tc1"] == 0:
                        self._exchange(int(m.fields["ts1"]))
                    else:
                        self.ctl.on_message(m)
                if self.last_tick >= last_exchange:
                    break
        finally:
            self.sock.close()
        return self.finish()

    def _exchange(self, ts1_ns: int) -> None:
        tick = round(ts1_ns * self.hz / 1e9)
        self.last_tick = tick
        self.exchanges += 1
        self.mon.update(tick, self.ctl.positions_ned_m())
        if self.ctl.due(tick):
            for o in self.ctl.step(tick):
                self._send(o.name, o.fields)
        self._collect()
        self._send("TIMESYNC", {"tc1": max(1, time.monotonic_ns()), "ts1": ts1_ns})

    def _collect(self) -> None:
        for kind, tick, fields in self.ctl.drain_events():
            self.mon.phase_event(tick, fields)
            self.events.append({"event": kind, "tick": tick, "time_s": tick / self.hz, **fields})
        for kind, tick, fields in self.mon.drain_events():
            self.events.append({"event": kind, "tick": tick, "time_s": tick / self.hz, **fields})

    def finish(self) -> dict[str, Any]:
        from cosim.swarm.participant import merged_summary, write_swarm_outputs

        # the run ends one exchange after the last one seen (its final step), as
        # the in-process participant's finish(tick) has it
        tick = self.last_tick + self.scn.rates.control_every if self.last_tick >= 0 else 0
        self.ctl.end_run(tick)
        self._collect()
        summary = merged_summary(self.ctl, self.mon)
        summary["exchanges"] = self.exchanges
        summary["metrics_from"] = "telemetry"
        if self.out is not None:
            self.out.mkdir(parents=True, exist_ok=True)
            (self.out / "swarm.json").write_text(json.dumps(summary, indent=1))
            with open(self.out / "swarm_events.jsonl", "w") as f:
                for e in self.events:
                    f.write(json.dumps(e) + "\n")
            write_swarm_outputs(self.out, self.ctl, self.mon, self.scn.name)
        return summary
