"""The MAVLink endpoint: every simulated vehicle of one link as a MAVLink
vehicle on one UDP socket, driven once per exchange by the lockstep loop.

Usage (the runner, once per exchange; ``MavlinkLinks`` has the same
interface for runs of more than 240 vehicles)::

    specs = mav_specs(scenario.vehicles, get_class)
    with MavlinkEndpoint(specs, physics_hz, MavlinkConfig(url), tlog_dir=out) as mav:
        while ...:
            for vc in mav.receive(tick, states):
                guidance.command([vc.row], vc.command, states, pool.setpoints)
            guidance.update(states, pool.setpoints)
            pool.send(k)
            mav.send_telemetry(tick)  # while the workers step
            states = pool.wait()
            tick += k
        summary["mavlink"] = mav.counters()

``receive(tick, states)`` takes the state rows at ``tick``, handles every
message waiting (bounded: the network's, ``cosim.mavlink.inbox``; those
in-process clients injected; missions loaded from inside cosim), follows the
missions being flown and returns the guidance commands produced, in arrival
order (a mission flown in AUTO is one command per item; its progress is
followed from the state rows). ``send_telemetry(tick)`` sends the streams due
(``cosim.mavlink.telemetry``). ``exchange`` is the two. Nothing that arrives
from the network makes it block or raise: problems are counted
(``counters()``). The parts it drives: ``inbox`` (decoding, signing
checks), ``lockstep`` (an outside controller), ``router`` (each message to
its vehicles and their services), ``outbox`` (packets to the peers, the
in-process subscribers and the tlogs), ``telemetry``.

With signing on, every packet the vehicles send is signed with the key and
``signing_link_id``; signature timestamps follow the wall clock (10 us units
since 2015-01-01), as the specification asks, not the simulation clock, and
never go back: each vehicle signs above any timestamp the key has seen in
earlier runs, kept with the replay protection (``cosim.mavlink.signing``).

In-process clients (the swarm controller) use the same messages without a
socket: ``subscribe(callback)`` delivers every packet a vehicle sends as a
``Message`` (float fields rounded to float32 as a receiver decodes them, so
an in-process client sees exactly what a network client sees), and
``inject(message)`` queues a message handled at the next exchange exactly as
if it came from the network.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.state import N_STATE
from cosim.errors import ConfigError
from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.config import MavlinkConfig, load_signing_key
from cosim.mavlink.errors import EndpointClosed
from cosim.mavlink.handlers import Handler
from cosim.mavlink.inbox import Inbox, Received
from cosim.mavlink.link import NullLink, UdpLink
from cosim.mavlink.lockstep import Lockstep
from cosim.mavlink.outbox import Outbox
from cosim.mavlink.params import FollowedParams
from cosim.mavlink.router import Router, VehicleCommand
from cosim.mavlink.signing import SharedSigning
from cosim.mavlink.telemetry import Telemetry
from cosim.mavlink.vehicle import MavVehicle, MavVehicleSpec, SimClock, StateFrame, check_rates

log = logging.getLogger(__name__)

#: vehicles one endpoint carries (system ids are 8 bits and ground stations
#: use 255 and up); more need a second endpoint on its own URL, serving its
#: own ground station: ``mav_specs(vehicles[240:], classes, first_sysid=1, first_row=240)``
MAX_VEHICLES_PER_LINK = 240

#: the system id of cosim's own controllers (the swarm controller) on MAVLink,
#: in-process or outside (``cosim run --external-controller``)
CONTROLLER_SYSID = 245

#: counters always present in ``counters()``
ENDPOINT_COUNTERS = (
    "packets_out", "echoes", "unknown_target_system", "other_component", "gcs_heartbeats",
    "ignored_messages", "unsupported_commands", "commands_refused", "commands_unsafe",
    "commands_out",
    "handler_errors", "param_unknown", "param_rejected", "ftp_naks",
    "position_targets_ignored", "position_targets_invalid", "position_targets_unsupported",
    "injected", "mission_uploads", "mission_upload_errors", "mission_upload_timeouts",
    "mission_rerequests", "mission_unexpected", "mission_downloads", "mission_items_reached",
    "unsigned_dropped", "mavlink1_dropped", "bad_signature_dropped", "replay_dropped",
    "stale_stream_dropped", "setup_signing_ignored")

#: the signing state is saved at most this often (wall clock) and at close
SIGNING_SAVE_S = 1.0


class MavlinkEndpoint:
    """Vehicles on one MAVLink link (see the module docstring).

    ``vehicles``: one ``MavVehicleSpec`` each (``mav_specs`` builds them
    from scenario vehicles); ``physics_hz``: ticks per simulated second;
    ``tlog_dir``: folder for one ``<vehicle>.tlog`` each (None: no tlogs);
    ``clock_anchor_unix_us``: the wall-clock instant of tick 0 in
    SYSTEM_TIME and tlogs (default: the start of the current second, so
    real-time runs show the wall clock; pass a fixed value for
    reproducible tlogs); ``signing``: the replay protection shared with the
    run's other links (None: its own, when the config signs).
    """

    def __init__(self, vehicles: Sequence[MavVehicleSpec], physics_hz: float,
                 config: MavlinkConfig | None = None, tlog_dir: str | Path | None = None,
                 clock_anchor_unix_us: int | None = None,
                 signing: SharedSigning | None = None) -> None:
        config = config or MavlinkConfig()
        _check(vehicles, physics_hz, config)
        key = load_signing_key(config)
        anchor = clock_anchor_unix_us if clock_anchor_unix_us is not None \
            else int(time.time()) * 1_000_000
        self.clock = SimClock(float(physics_hz), int(anchor))
        self.config = config
        self.frame = StateFrame()  # this exchange's rows, read by vehicles on demand
        self.vehicles = [MavVehicle(s, self.clock, config.rates_hz, self.frame, i)
                         for i, s in enumerate(vehicles)]
        #: the key's replay protection, shared with the run's other links and,
        #: through its file, with other runs (None: signing off)
        self.signing: SharedSigning | None = None
        self._owns_signing = False
        self._signing_saved = time.monotonic()
        #: the signature stream of each vehicle's packets
        self._own_streams = [(config.signing_link_id, v.sysid, mav.MAV_COMP_ID_AUTOPILOT1)
                             for v in self.vehicles]
        if key is not None:
            self._owns_signing = signing is None
            self.signing = signing or SharedSigning(key, config.signing_state_dir)
            start = self.signing.add_own(self._own_streams)
            for v in self.vehicles:
                v.packer.enable_signing(key, config.signing_link_id)
                v.packer.advance_signing_time(start)
        self._by_sysid = {v.sysid: v for v in self.vehicles}
        self._by_row = {v.row: v for v in self.vehicles}
        self.counts: Counter[str] = Counter({k: 0 for k in ENDPOINT_COUNTERS})
        self.handler = Handler(self.counts, self.clock.physics_hz)
        self._injected: list[mav.Message] = []
        self._loads: list[tuple[int, list[Any], bool]] = []  # load_mission, not yet done
        self._last_tick: int | None = None
        self._rows = np.array([v.row for v in self.vehicles], dtype=np.intp)
        self._rows_needed = int(self._rows.max(initial=-1)) + 1  # state rows receive() reads
        self._followed = FollowedParams(self.vehicles)
        #: run events from the vehicles (a fence breach): (row, kind, fields)
        self.events: list[tuple[int, str, dict[str, Any]]] = []
        self.link: UdpLink | NullLink = NullLink() if config.url is None else UdpLink(
            config.url, config.max_peers, config.max_datagrams_per_exchange)
        if not self.link.loopback and key is None:
            host, port = self.link.local_address
            log.warning("mavlink %s: listening on %s:%d, which other machines can reach, "
                        "WITHOUT signing: anyone who can send to it can command every vehicle "
                        "(modes, arming, gotos, parameters, missions). Keep it on 127.0.0.1, "
                        "or sign: --mavlink-signing-key-file PATH or "
                        "--mavlink-signing-key-env NAME", config.url, host, port)
        self.inbox = Inbox(self.link, self.counts, self.signing)
        self.lockstep = Lockstep(self.clock)
        self.outbox = Outbox(self.vehicles, self.clock, self.link, self.counts,
                             signing=key is not None)
        self.router = Router(self.vehicles, self.handler, self.outbox, self.counts)
        self.telemetry = Telemetry(self.vehicles, self.clock, self.frame, self.outbox,
                                   self.counts)
        try:
            if tlog_dir is not None:
                self.outbox.open_tlogs(tlog_dir)
        except BaseException:
            self.close()
            raise

    # -- lifecycle -------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self.link.closed

    @property
    def local_address(self) -> tuple[str, int]:
        """Where the socket is bound (ground stations using udpout send here)."""
        return self.link.local_address

    def __enter__(self) -> MavlinkEndpoint:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Flush and close the tlogs and the socket, save the signing state
        (safe to call twice)."""
        self.outbox.close_tlogs()
        if not self.link.closed:
            self._save_signing(force=True)
        self.link.close()

    @property
    def signature_checker(self) -> mav.SignatureChecker | None:
        """Verifies incoming signatures (None: signing off)."""
        return None if self.signing is None else self.signing.checker

    def _save_signing(self, force: bool = False) -> None:
        """Keep the vehicles' signing timestamps for later runs (at most once a
        second unless ``force``: they advance with every packet sent)."""
        if self.signing is None:
            return
        now = time.monotonic()
        if not force and now - self._signing_saved < SIGNING_SAVE_S:
            return
        self._signing_saved = now
        self.signing.save_sent({s: v.packer.signing_timestamp
                                for s, v in zip(self._own_streams, self.vehicles)})
        if force and self._owns_signing:
            self.signing.close()

    # -- in-process clients and cosim itself -----------------------------------
    def inject(self, message: mav.Message) -> None:
        """Queue a message to be handled at the next exchange exactly as if it had
        arrived from the network (for in-process clients: one command path)."""
        if self.closed:
            raise EndpointClosed("mavlink endpoint: inject() after close()")
        self._injected.append(message)

    def subscribe(self, callback: Callable[[mav.Message], None]) -> None:
        """Call ``callback(message)`` for every packet any vehicle sends from now
        on (telemetry and answers), in sending order, as an in-process client
        would receive it (see the module docstring)."""
        self.outbox.subscribers.append(callback)

    def load_mission(self, row: int, items: Sequence[Any], fly: bool = True) -> None:
        """Put a mission (``cosim.mavlink.mission.MissionItem``, seq 1..n) on
        board the vehicle at state row ``row`` as a completed upload would,
        at the next exchange, and with ``fly`` switch it to its mission mode
        (a plan loaded before take-off, as an autopilot loads one from its
        storage): a ground station downloads it and watches it flown."""
        if self.closed:
            raise EndpointClosed("mavlink endpoint: load_mission() after close()")
        v = self._by_row.get(row)
        if v is None:
            raise KeyError(f"no vehicle at state row {row} on this link")
        if v.personality.auto_mode is None or not v.personality.autopilot:
            raise ValueError(f"vehicle {v.spec.name} flies no missions")
        self._loads.append((row, list(items), fly))

    def local_command(self, row: int, command: Command) -> Command:
        """A command from inside cosim (the schedule) for the vehicle at state
        row ``row``: its MAVLink state follows (``Handler.local_command``), so
        the next heartbeat shows the mode; returns the command for guidance."""
        v = self._by_row.get(row)
        return command if v is None else self.handler.local_command(v, command)

    def set_video(self, streams: Mapping[int, Sequence[Mapping[str, Any]]]) -> None:
        """The video streams each vehicle (by system id) answers
        VIDEO_STREAM_INFORMATION with (stream ids 1.., their count)."""
        for sysid, infos in streams.items():
            v = self._by_sysid.get(sysid)
            if v is not None:
                v.video = [{**i, "stream_id": k + 1, "count": len(infos)}
                           for k, i in enumerate(infos)]

    # -- per exchange ----------------------------------------------------------
    def exchange(self, tick: int, states: np.ndarray) -> list[VehicleCommand]:
        """Handle what arrived, send what is due at ``tick``; the commands produced.
        (``receive`` then ``send_telemetry``.)"""
        commands = self.receive(tick, states)
        self.send_telemetry(tick)
        return commands

    def receive(self, tick: int, states: np.ndarray) -> list[VehicleCommand]:
        """The first half of ``exchange``: take the state rows at ``tick`` (a
        copy), handle every message waiting; the commands produced. The
        runner calls ``send_telemetry(tick)`` next, after starting the pool's
        step, so that telemetry overlaps the workers' physics."""
        self._observe(tick, states)
        commands: list[VehicleCommand] = []
        self._load_missions(tick, commands)
        injected, self._injected = self._injected, []
        for m in injected:
            self.counts["injected"] += 1
            self.router.dispatch(m, tick, commands)
        for msgs, addr in self._network(tick):
            heard = sum(not self.router.echo(m) for m in msgs)
            if heard:  # our own packets sent back make no sender a peer
                self.link.remember(addr, heard)
            for m in msgs:
                self.router.dispatch(m, tick, commands, addr)
        self._fly_missions(tick, commands)
        self.counts["commands_out"] += len(commands)
        return commands

    def send_telemetry(self, tick: int) -> None:
        """The second half of ``exchange``: every stream due at ``tick``, from
        the rows ``receive(tick, ...)`` took, then in lockstep the TIMESYNC
        request."""
        if self._last_tick != tick:
            raise ValueError(f"mavlink send_telemetry: tick {tick} is not the tick of the last "
                             f"receive ({self._last_tick})")
        self.telemetry.send(tick)
        if self.config.lockstep_sysid is not None:
            self.outbox.send(self.vehicles[0], "TIMESYNC", self.lockstep.request(tick), tick)
        self.outbox.flush()
        self._save_signing()

    def drain_events(self) -> list[tuple[int, str, dict[str, Any]]]:
        """Run events since the last call: (state row, kind, fields)."""
        events, self.events = self.events, []
        return events

    def counters(self) -> dict[str, int]:
        """Every counter (decoding, link, handling), for summary.json."""
        out: dict[str, int] = {}
        self.link.update_kernel_drops()
        out.update(self.inbox.decoder.counts)
        out.update(self.link.counts)
        out.update(self.counts)
        out["peers"] = len(self.link.peers)
        out["tlog_records"] = self.outbox.tlog_records
        return dict(sorted(out.items()))

    # -- the steps of receive --------------------------------------------------
    def _observe(self, tick: int, states: np.ndarray) -> None:
        """The vehicles' state rows at ``tick``; the parameters that follow a
        state column announced where they changed."""
        if self.closed:
            raise EndpointClosed(f"mavlink endpoint: exchange(tick={tick}) after close()")
        if self._last_tick is not None and tick < self._last_tick:
            raise ValueError(f"mavlink receive: tick {tick} is before the previous "
                             f"exchange's tick {self._last_tick}")
        rows = self._rows_needed
        if states.ndim != 2 or states.shape[0] < rows or states.shape[1] < N_STATE:
            raise ValueError(f"mavlink receive: states must be (n >= {rows}, {N_STATE}), "
                             f"got {states.shape}")
        self._last_tick = tick
        mine = states[self._rows]
        self.frame.observe(mine, tick, self.clock.physics_hz)
        for v, name in self._followed.sync(mine):  # announced on change, as ArduPilot does
            self.outbox.send(v, *self.handler.param_value(v, name), tick)

    def _load_missions(self, tick: int, commands: list[VehicleCommand]) -> None:
        """The missions ``load_mission`` queued, on board (and flown)."""
        loads, self._loads = self._loads, []
        for row, items, fly in loads:
            v = self._by_row[row]
            out = self.handler.load_mission(v, items, fly, tick)
            for name, fields in out.replies:
                self.outbox.send(v, name, fields, tick)
            commands.extend(VehicleCommand(v.row, c, "mission") for c in out.commands)

    def _network(self, tick: int) -> Received:
        """The datagrams waiting, decoded; in lockstep, first the controller's
        answer (``cosim.mavlink.lockstep``)."""
        got = self.inbox.poll()
        sysid = self.config.lockstep_sysid
        if sysid is None:
            return got
        return self.lockstep.wait(got, self.inbox.poll, self.link, tick, sysid,
                                  self.config.lockstep_timeout_s)

    def _fly_missions(self, tick: int, commands: list[VehicleCommand]) -> None:
        """Missions flown and the fence, after the messages."""
        for v in self.vehicles:
            if v.mission.busy():
                out = self.handler.mission_update(v, tick)
                for name, fields in out.replies:
                    self.outbox.send(v, name, fields, tick)
                commands.extend(VehicleCommand(v.row, c, "mission") for c in out.commands)
                self.events.extend((v.row, kind, f) for kind, f in out.events)


def _check(vehicles: Sequence[MavVehicleSpec], physics_hz: float, config: MavlinkConfig
           ) -> None:
    """ConfigError listing every problem of an endpoint's arguments."""
    problems = check_rates(config.rates_hz)
    if not physics_hz > 0:
        problems.append(f"physics_hz must be > 0, got {physics_hz!r}")
    if len(vehicles) > MAX_VEHICLES_PER_LINK:
        problems.append(f"{len(vehicles)} vehicles on one MAVLink link; at most "
                        f"{MAX_VEHICLES_PER_LINK} (use a second link for the rest)")
    for what, values in (("system id", [v.sysid for v in vehicles]),
                         ("row", [v.row for v in vehicles])):
        dup = sorted({x for x in values if values.count(x) > 1})
        if dup:
            problems.append(f"duplicate vehicle {what}(s): {dup}")
    if problems:
        raise ConfigError([f"mavlink: {p}" for p in problems])
