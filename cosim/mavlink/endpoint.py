"""The MAVLink endpoint: every simulated vehicle as a MAVLink vehicle on one
UDP socket, driven once per exchange by the lockstep loop.

Usage (the runner, once per exchange; ``MavlinkLinks`` has the same
interface for runs of more than 240 vehicles)::

    specs = mav_specs(scenario.vehicles)
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

``exchange(tick, states)`` (``receive`` then ``send_telemetry``) reads
every datagram waiting (bounded), answers
them (ACKs, parameters, requested messages), sends the telemetry due at
``tick`` from ``states`` (the state array at ``tick``), writes both
directions to the tlogs, and returns the guidance commands the messages
produced, in arrival order (a mission flown in AUTO is one ``waypoints``
command; its progress is followed from ``states``, no guidance events
needed). It never blocks and never raises because of
what arrives from the network; problems are counted (``counters()``).

MAVLink 2 signing (``MavlinkConfig.signing_key_file`` / ``signing_key_env``,
``cosim.mavlink.config``):

- every packet the vehicles send is signed with the key and
  ``signing_link_id``; the signature timestamp follows the WALL clock (10 us
  units since 2015-01-01), as the specification asks, not the simulation
  clock (which runs ahead of it in a run faster than real time), and never
  goes back (each vehicle's packets carry strictly increasing timestamps,
  starting above any timestamp this key has seen in earlier runs);
- a received packet is handled only if it carries a valid signature made
  with the same key and a timestamp newer than the last accepted one of its
  stream (link id, system, component), or, for a stream not seen before,
  not more than a minute behind the newest timestamp known; otherwise it is
  dropped before anything looks at it and counted: ``unsigned_dropped``,
  ``bad_signature_dropped`` (wrong key, tampered), ``replay_dropped``,
  ``stale_stream_dropped``. MAVLink 1 packets cannot be signed, so they are
  dropped too (counted in ``unsigned_dropped`` and, separately,
  ``mavlink1_dropped``);
- the timestamps are shared with the run's other links (``signing``, a
  ``SharedSigning``) and, through a file under a lock, with every run using
  the key (``cosim.mavlink.signing``): a signed packet accepted on any link
  of any run, or read from a tlog, is a replay everywhere else, whatever its
  link id;
- a correctly signed packet from one of our vehicles (its own stream, or its
  system id with component 1) is our own packet sent back: dropped
  (``echoes``);
- only a sender of an accepted packet that is not an echo becomes a peer
  (gets telemetry): a ground station without the key receives nothing from
  a ``udpin`` link (from ``udpout`` it receives packets it cannot verify),
  even by reflecting the vehicles' signed packets;
- SETUP_SIGNING is never obeyed, even correctly signed
  (``setup_signing_ignored``): the key comes from the operator only;
- ``inject()``-ed messages are in-process, not checked.

In-process clients (the swarm controller) use the same messages without a
socket: ``subscribe(callback)`` delivers every packet a vehicle sends as a
``Message`` (float fields rounded to float32 as a receiver decodes them, so
an in-process client sees exactly what a network client sees), and
``inject(message)`` queues a message handled at the next exchange exactly as
if it came from the network.

Lockstep with an outside controller (``MavlinkConfig.lockstep_sysid``), so
that a controller in another process gives the same results as in-process:

- after the telemetry of every exchange at tick T, vehicle 1 sends
  TIMESYNC ``tc1=0, ts1=T's simulation time in ns`` (an ordinary time-sync
  request);
- the controller reads the telemetry, sends its commands, then answers the
  request as the TIMESYNC protocol says (``tc1`` its clock, non-zero;
  ``ts1`` echoed);
- the next exchange first waits (at most ``lockstep_timeout_s``, else
  ``LockstepTimeout``) for that answer from the controller's system id, then
  handles everything received: the commands take effect at the same tick as
  an in-process controller's ``inject``-ed ones. The first exchange waits
  for any message from the controller (it says hello with a HEARTBEAT).
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from cosim.core.state import N_STATE, STATE_INDEX
from cosim.errors import ConfigError
from cosim.guidance.commands import Command
from cosim.mavlink import adapter as mav
from cosim.mavlink.batch import BatchEncoder
from cosim.mavlink.config import MavlinkConfig, load_signing_key
from cosim.mavlink.errors import EndpointClosed, LockstepTimeout
from cosim.mavlink.handlers import Handler
from cosim.mavlink.link import NullLink, UdpLink
from cosim.mavlink.outcome import Outcome, command_ack
from cosim.mavlink.signing import SharedSigning
from cosim.mavlink.tlog import STAMP_LEN as TLOG_STAMP_LEN
from cosim.mavlink.tlog import TlogWriter
from cosim.mavlink.tlog import stamp as tlog_stamp
from cosim.mavlink.vehicle import (
    ATTITUDE_COLUMNS,
    STATE_COLUMNS,
    STREAMABLE,
    MavVehicle,
    MavVehicleSpec,
    SimClock,
    StateFrame,
    body_rates,
    check_rates,
    safe_name,
)

log = logging.getLogger(__name__)

#: vehicles one endpoint carries (system ids are 8 bits and ground stations
#: use 255 and up); more need a second endpoint on its own URL, serving its
#: own ground station: ``mav_specs(vehicles[240:], first_sysid=1, first_row=240)``
MAX_VEHICLES_PER_LINK = 240

#: the system id of cosim's own controllers (the swarm controller) on MAVLink,
#: in-process or outside (``cosim run --external-controller``)
CONTROLLER_SYSID = 245

#: tlogs are written to disk at most this often (wall clock) and at close:
#: a hard crash loses at most this much of them
TLOG_FLUSH_S = 0.5

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


class VehicleCommand(NamedTuple):
    """A command for guidance: apply ``command`` to state row ``row``."""

    row: int
    command: Command
    #: what it came from, e.g. ``"COMMAND_INT MAV_CMD_DO_REPOSITION from 255/190"``
    origin: str


def _origin(m: mav.Message) -> str:
    what = m.name
    if m.name in ("COMMAND_LONG", "COMMAND_INT"):
        what += f" {mav.command_name(int(m.fields['command']))}"
    src = "in-process" if not m.raw else f"from {m.src_system}/{m.src_component}"
    return f"{what} {src}"


@dataclass
class _Followed:
    """A parameter following a state column (``Personality.followed_params``)
    on the vehicles in ``mask``, its values as last synced."""

    name: str
    column: int
    mask: np.ndarray
    lo: float
    hi: float
    last: np.ndarray


def _followed_params(vehicles: Sequence[MavVehicle]) -> list[_Followed]:
    pairs = sorted({(n, c) for v in vehicles for n, c in v.personality.followed_params.items()})
    out = []
    for name, column in pairs:
        if column not in STATE_INDEX:
            raise ValueError(f"parameter {name} follows {column!r}, not a state column; "
                             f"known: {', '.join(STATE_INDEX)}")
        mask = np.array([v.personality.followed_params.get(name) == column for v in vehicles],
                        dtype=bool)
        p = next(v.params.defs[v.params.index[name]] for v, m in zip(vehicles, mask) if m)
        out.append(_Followed(name, STATE_INDEX[column], mask, p.lo, p.hi,
                             np.full(len(vehicles), np.nan)))
    return out


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
        self.decoder = mav.Decoder()
        self.handler = Handler(self.counts, self.clock.physics_hz)
        self._injected: list[mav.Message] = []
        self._loads: list[tuple[int, list[Any], bool]] = []  # load_mission, not yet done
        self._last_tick: int | None = None
        self._rows = np.array([v.row for v in self.vehicles], dtype=np.intp)
        self._rows_needed = int(self._rows.max(initial=-1)) + 1  # state rows receive() reads
        self._zero_rates = np.zeros((len(self.vehicles), 3))
        self._prev_att: np.ndarray | None = None
        self._followed = _followed_params(self.vehicles)
        self._sysids = np.array([v.sysid for v in self.vehicles], dtype=np.int64)
        self._home_alt = np.array([v.home[2] for v in self.vehicles], dtype=float)
        # stream schedule over all vehicles: period and next-due tick per
        # (message, vehicle); -1 = off / not yet sent (see vehicle.py's due())
        n = len(self.vehicles)
        self._period = np.full((len(STREAMABLE), n), -1, dtype=np.int64)
        self._next_due = np.full((len(STREAMABLE), n), -1, dtype=np.int64)
        for j, v in enumerate(self.vehicles):
            v.on_period_change = self._period_changed
            for k, name in enumerate(STREAMABLE):
                p = v.period[name]
                self._period[k, j] = -1 if p is None else p
        self._encoders = {name: BatchEncoder(name) for name in STREAMABLE}
        self._first_due = -1  # the earliest next-due tick of any stream
        #: each vehicle's next sequence number (the batches and its packer share it)
        self._seq = np.zeros(n, dtype=np.int64)
        self._tlog_flushed = time.monotonic()
        self.tlogs: dict[int, TlogWriter] = {}
        #: run events from the vehicles (a fence breach): (row, kind, fields)
        self.events: list[tuple[int, str, dict[str, Any]]] = []
        #: encoders of in-process clients' messages for the tlogs, by (system, component)
        self._client_packers: dict[tuple[int, int], mav.Packer] = {}
        self.link: UdpLink | NullLink = NullLink() if config.url is None else UdpLink(
            config.url, config.max_peers, config.max_datagrams_per_exchange)
        if not self.link.loopback and key is None:
            host, port = self.link.local_address
            log.warning("mavlink %s: listening on %s:%d, which other machines can reach, "
                        "WITHOUT signing: anyone who can send to it can command every vehicle "
                        "(modes, arming, gotos, parameters, missions). Keep it on 127.0.0.1, "
                        "or sign: --mavlink-signing-key-file PATH or "
                        "--mavlink-signing-key-env NAME", config.url, host, port)
        self._subscribers: list[Callable[[mav.Message], None]] = []
        self._lockstep_pending: int | None = None  # the tick whose answer is awaited
        self._lockstep_seen = False  # the controller has spoken
        try:
            if tlog_dir is not None:
                used: set[str] = set()
                for v in self.vehicles:
                    stem = safe_name(v.spec.name)
                    if stem in used:
                        stem = f"{stem}-sys{v.sysid}"
                    used.add(stem)
                    self.tlogs[v.sysid] = TlogWriter(Path(tlog_dir) / f"{stem}.tlog")
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
        for t in self.tlogs.values():
            t.close()
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

    # -- per exchange ----------------------------------------------------------
    def inject(self, message: mav.Message) -> None:
        """Queue a message to be handled at the next exchange exactly as if it had
        arrived from the network (for in-process clients: one command path)."""
        if self.closed:
            raise EndpointClosed("mavlink endpoint: inject() after close()")
        self._injected.append(message)

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

    def subscribe(self, callback: Callable[[mav.Message], None]) -> None:
        """Call ``callback(message)`` for every packet any vehicle sends from now
        on (telemetry and answers), in sending order, as an in-process client
        would receive it (see the module docstring)."""
        self._subscribers.append(callback)

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
        if self.closed:
            raise EndpointClosed(f"mavlink endpoint: exchange(tick={tick}) after close()")
        if self._last_tick is not None and tick < self._last_tick:
            raise ValueError(f"mavlink receive: tick {tick} is before the previous "
                             f"exchange's tick {self._last_tick}")
        rows = self._rows_needed
        if states.ndim != 2 or states.shape[0] < rows or states.shape[1] < N_STATE:
            raise ValueError(f"mavlink receive: states must be (n >= {rows}, {N_STATE}), "
                             f"got {states.shape}")
        prev_tick, self._last_tick = self._last_tick, tick
        mine = states[self._rows]
        att = mine[:, ATTITUDE_COLUMNS]
        prev_att, self._prev_att = self._prev_att, att
        if prev_att is not None and prev_tick is not None and tick > prev_tick:
            dt_s = (tick - prev_tick) / self.clock.physics_hz
            self.frame.update(mine, lambda: body_rates(prev_att, att, dt_s))
        else:  # the first exchange, or the same tick again: the rates stand
            self.frame.update(mine, self._last_rates)
        for f in self._followed:  # parameters following a state column, announced
            values = mine[:, f.column]  # on change, as ArduPilot does (ROLL_LIMIT_DEG)
            changed = f.mask & (values != f.last) & (values >= f.lo) & (values <= f.hi)
            if changed.any():
                for j in np.flatnonzero(changed).tolist():
                    v = self.vehicles[j]
                    before = v.params[f.name]
                    v.params.force(f.name, float(values[j]))
                    if v.params[f.name] != before:
                        self._send(v, *self.handler.param_value(v, f.name), tick)
                f.last = np.where(changed, values, f.last)
        commands: list[VehicleCommand] = []
        loads, self._loads = self._loads, []
        for row, items, fly in loads:
            v = self._by_row[row]
            out = self.handler.load_mission(v, items, fly, tick)
            for name, fields in out.replies:
                self._send(v, name, fields, tick)
            commands.extend(VehicleCommand(v.row, c, "mission") for c in out.commands)
        injected, self._injected = self._injected, []
        for m in injected:
            self.counts["injected"] += 1
            self._dispatch(m, tick, commands)
        for msgs, addr in self._receive(tick):
            heard = sum(not self._echo(m) for m in msgs)
            if heard:  # our own packets sent back make no sender a peer
                self.link.remember(addr, heard)
            for m in msgs:
                self._dispatch(m, tick, commands, addr)
        for v in self.vehicles:  # missions flown and the fence, after the messages
            if v.mission.busy():
                out = self.handler.mission_update(v, tick)
                for name, fields in out.replies:
                    self._send(v, name, fields, tick)
                commands.extend(VehicleCommand(v.row, c, "mission") for c in out.commands)
                self.events.extend((v.row, kind, f) for kind, f in out.events)
        self.counts["commands_out"] += len(commands)
        return commands

    def set_video(self, streams: Mapping[int, Sequence[Mapping[str, Any]]]) -> None:
        """The video streams each vehicle (by system id) answers
        VIDEO_STREAM_INFORMATION with (stream ids 1.., their count)."""
        for sysid, infos in streams.items():
            v = self._by_sysid.get(sysid)
            if v is not None:
                v.video = [{**i, "stream_id": k + 1, "count": len(infos)}
                           for k, i in enumerate(infos)]

    def drain_events(self) -> list[tuple[int, str, dict[str, Any]]]:
        """Run events since the last call: (state row, kind, fields)."""
        events, self.events = self.events, []
        return events

    def send_telemetry(self, tick: int) -> None:
        """The second half of ``exchange``: mission progress and every stream
        due at ``tick``, from the rows ``receive(tick, ...)`` took."""
        if self._last_tick != tick:
            raise ValueError(f"mavlink send_telemetry: tick {tick} is not the tick of the last "
                             f"receive ({self._last_tick})")
        self._telemetry(tick)
        if self.config.lockstep_sysid is not None:
            self._send(self.vehicles[0], "TIMESYNC",
                       {"tc1": 0, "ts1": self.clock.sim_us(tick) * 1000}, tick)
            self._lockstep_pending = tick
        now = time.monotonic()
        if now - self._tlog_flushed >= TLOG_FLUSH_S:
            self._tlog_flushed = now
            for t in self.tlogs.values():
                t.flush()
        self._save_signing()

    def counters(self) -> dict[str, int]:
        """Every counter (decoding, link, handling), for summary.json."""
        out: dict[str, int] = {}
        self.link.update_kernel_drops()
        out.update(self.decoder.counts)
        out.update(self.link.counts)
        out.update(self.counts)
        out["peers"] = len(self.link.peers)
        out["tlog_records"] = sum(t.records for t in self.tlogs.values())
        return dict(sorted(out.items()))

    # -- internals -------------------------------------------------------------
    @property
    def _last_rates(self) -> np.ndarray:
        """Body rates at the latest exchange (zeros before the second)."""
        r = self.frame.rates
        return self._zero_rates if r is None else r

    def _period_changed(self, v: MavVehicle, name: str) -> None:
        k, j = STREAMABLE.index(name), v.index
        p = v.period[name]
        self._period[k, j] = -1 if p is None else p
        nd = v.next_due[name]
        self._next_due[k, j] = -1 if nd is None else nd
        self._first_due = -1  # recomputed at the next exchange

    def _telemetry(self, tick: int) -> None:
        """Send every stream due at ``tick``, one message type for all due
        vehicles at once; the next-due ticks move on by whole periods (the
        rule of ``MavVehicle.due``)."""
        if tick < self._first_due:  # nothing due before then (most exchanges)
            return
        on = self._period > 0
        nd = np.where(on & (self._next_due < 0), tick, self._next_due)
        due = on & (nd <= tick)
        p = np.where(on, self._period, 1)
        self._next_due = np.where(due, nd + p * ((tick - nd) // p + 1), nd)
        self._first_due = int(self._next_due[on].min()) if on.any() else 2 ** 62
        if not due.any():
            return
        signing = self.signing is not None
        seq = None if signing else self._seq
        blobs: list[bytes] = []
        lengths: list[np.ndarray] = []
        who: list[np.ndarray] = []
        unix_us = self.clock.unix_us(tick)
        for k in np.flatnonzero(due.any(axis=1)).tolist():
            name = STREAMABLE[k]
            idx = np.flatnonzero(due[k])
            vs = [self.vehicles[j] for j in idx.tolist()]
            if signing:  # each packet signed by pymavlink
                for v in vs:
                    self._send(v, name, v.fields(name, tick), tick)
                continue
            assert seq is not None
            build = STATE_COLUMNS.get(name)
            if build is not None:
                rows = self.frame.rows
                assert rows is not None
                # only ATTITUDE reads the body rates: the others need not compute them
                pqr = self._last_rates if name == "ATTITUDE" else self._zero_rates
                cols = build(rows[idx], pqr[idx], self._home_alt[idx], self.clock, tick)
            else:
                dicts = [v.fields(name, tick) for v in vs]
                cols = {f: [d[f] for d in dicts] for f in dicts[0]}
            enc = self._encoders[name]
            rec = enc.payloads(len(idx), cols)
            blob, lens = enc.encode(rec, self._sysids[idx], seq[idx])
            seq[idx] = (seq[idx] + 1) % 256
            self.counts["packets_out"] += len(idx)
            blobs.append(blob)
            lengths.append(lens)
            who.append(idx)
            if self._subscribers:
                self._deliver_batch(name, vs, rec)
        if blobs:
            blob = b"".join(blobs)
            lens = np.concatenate(lengths)
            self.link.send_packets(blob, lens.tolist())
            if self.tlogs:
                self._tlog_batch(blob, lens, np.concatenate(who), unix_us)

    def _deliver_batch(self, name: str, vs: list[MavVehicle], rec: np.ndarray) -> None:
        """A batch's packets to the subscribers, as messages."""
        names = self._encoders[name].field_names
        for v, values in zip(vs, rec.tolist()):
            m = mav.Message(name, v.sysid, mav.MAV_COMP_ID_AUTOPILOT1, dict(zip(names, values)))
            for cb in self._subscribers:
                cb(m)

    def _tlog_batch(self, blob: bytes, lens: np.ndarray, who: np.ndarray, unix_us: int) -> None:
        """An exchange's batched packets (vehicle index ``who`` each) into the
        tlogs: the records (stamp + packet) are laid out per vehicle in one
        numpy pass, then each tlog takes its run of records at once."""
        order = np.argsort(who, kind="stable")  # per vehicle, in sending order
        src_start = np.cumsum(lens) - lens
        n_sorted = lens[order]
        rec_len = n_sorted + TLOG_STAMP_LEN
        dst_start = np.cumsum(rec_len) - rec_len
        out = np.empty(int(rec_len.sum()), dtype=np.uint8)
        out[(dst_start[:, None] + np.arange(TLOG_STAMP_LEN)).ravel()] = np.tile(
            np.frombuffer(tlog_stamp(unix_us), dtype=np.uint8), len(order))
        total = int(n_sorted.sum())
        within = np.arange(total) - np.repeat(np.cumsum(n_sorted) - n_sorted, n_sorted)
        out[np.repeat(dst_start + TLOG_STAMP_LEN, n_sorted) + within] = np.frombuffer(
            blob, dtype=np.uint8)[np.repeat(src_start[order], n_sorted) + within]
        data = out.tobytes()
        w = who[order]
        firsts = np.flatnonzero(np.r_[True, w[1:] != w[:-1]])
        ends = np.r_[firsts[1:], len(w)]
        byte_at = np.r_[dst_start, len(out)]
        for j, a, b in zip(w[firsts].tolist(), firsts.tolist(), ends.tolist()):
            t = self.tlogs.get(self.vehicles[j].sysid)
            if t is not None:
                t.write_records(unix_us, data[byte_at[a]:byte_at[b]], b - a)

    def _poll(self) -> list[tuple[list[mav.Message], tuple[str, int]]]:
        """The datagrams waiting now, decoded (and authenticated: all at once,
        one look at the shared signing state), with their senders."""
        got = [(self.decoder.decode(data), addr) for data, addr in self.link.poll()]
        if self.signing is None:
            return got
        verdicts = iter(self.signing.authenticate([m.raw for msgs, _ in got for m in msgs]))
        return [([a for a in (self._authenticated(m, next(verdicts)) for m in msgs)
                  if a is not None], addr) for msgs, addr in got]

    def _receive(self, tick: int) -> list[tuple[list[mav.Message], tuple[str, int]]]:
        """The datagrams waiting, decoded; in lockstep, first wait for the
        controller (see the module docstring)."""
        got = self._poll()
        sysid = self.config.lockstep_sysid
        if sysid is None:
            return got
        pending = self._lockstep_pending
        ts1 = None if pending is None else self.clock.sim_us(pending) * 1000

        def answered(batch: list[tuple[list[mav.Message], tuple[str, int]]]) -> bool:
            for msgs, _ in batch:
                for m in msgs:
                    if m.src_system != sysid:
                        continue
                    self._lockstep_seen = True
                    if ts1 is None or (m.name == "TIMESYNC" and m.fields["tc1"] != 0
                                       and m.fields["ts1"] == ts1):
                        return True
            return False

        done = answered(got)
        deadline = time.monotonic() + self.config.lockstep_timeout_s
        while not done:
            left = deadline - time.monotonic()
            if left <= 0 or isinstance(self.link, NullLink):
                what = ("message" if ts1 is None else
                        f"TIMESYNC answer for tick {pending}")
                raise LockstepTimeout(
                    f"mavlink lockstep: no {what} from the controller (system {sysid}) "
                    f"within {self.config.lockstep_timeout_s:g} s at tick {tick}; is it "
                    f"running and talking to {self.link.url}?")
            if self.link.wait_readable(min(left, 0.5)):
                batch = self._poll()
                got.extend(batch)
                done = answered(batch)
        self._lockstep_pending = None
        return got

    def _authenticated(self, m: mav.Message, verdict: str) -> mav.Message | None:
        """A received message if ``verdict`` (its signature's) is good (marked
        signed), else None, counted; SETUP_SIGNING is never obeyed."""
        if verdict != mav.SIG_OK:
            if verdict == mav.SIG_MAVLINK1:
                self.counts["mavlink1_dropped"] += 1
                self.counts["unsigned_dropped"] += 1
            elif verdict == mav.SIG_UNSIGNED:
                self.counts["unsigned_dropped"] += 1
            elif verdict == mav.SIG_BAD:
                self.counts["bad_signature_dropped"] += 1
            elif verdict == mav.SIG_STALE:
                self.counts["stale_stream_dropped"] += 1
            elif verdict == mav.SIG_OWN:  # a vehicle's own packet sent back
                self.counts["echoes"] += 1
            else:
                self.counts["replay_dropped"] += 1
            return None
        if m.name == "SETUP_SIGNING":
            # the key comes from the operator's file or variable, never the network
            self.counts["setup_signing_ignored"] += 1
            return None
        return replace(m, signed=True)

    def _send(self, v: MavVehicle, name: str, fields: dict[str, object], tick: int,
              to: tuple[str, int] | None = None) -> None:
        """Send one message from ``v`` to the peers (and ``to``: the sender of
        the message it answers)."""
        if self.signing is not None:
            v.packer.advance_signing_time(mav.wall_signing_timestamp())
        v.packer.seq = int(self._seq[v.index])  # one sequence per vehicle, batches included
        pkt = v.packer.pack(name, **fields)
        self._seq[v.index] = v.packer.seq
        self.link.send(pkt, also=to)
        if self._subscribers:
            m = mav.Message(name, v.sysid, mav.MAV_COMP_ID_AUTOPILOT1,
                            mav.wire_values(name, dict(fields)))
            for cb in self._subscribers:
                cb(m)
        self.counts["packets_out"] += 1
        t = self.tlogs.get(v.sysid)
        if t is not None:
            t.write(self.clock.unix_us(tick), pkt)

    def _client_bytes(self, m: mav.Message) -> bytes:
        """The packet an in-process client's message would have been on the
        network (for the tlogs: they hold what the vehicle received, whoever
        sent it)."""
        key = (m.src_system, m.src_component)
        packer = self._client_packers.get(key)
        if packer is None:
            if not 1 <= m.src_system <= 255:
                return b""
            packer = self._client_packers[key] = mav.Packer(m.src_system, m.src_component)
        try:
            return packer.pack(m.name, **m.fields)
        except (ValueError, TypeError, KeyError):
            return b""

    def _echo(self, m: mav.Message) -> bool:
        """Whether ``m`` came from the network as one of our vehicles (our own
        packet looped back by the network setup, or sent back by someone)."""
        return bool(m.raw) and m.src_system in self._by_sysid \
            and m.src_component == mav.MAV_COMP_ID_AUTOPILOT1

    def _dispatch(self, m: mav.Message, tick: int, commands: list[VehicleCommand],
                  sender: tuple[str, int] | None = None) -> None:
        if self._echo(m):
            self.counts["echoes"] += 1
            return
        tgt = m.target_system
        if tgt is None:  # not addressed to a vehicle (a ground station's HEARTBEAT, ...)
            self.counts["gcs_heartbeats" if m.name == "HEARTBEAT" else "ignored_messages"] += 1
            raw = m.raw or (self._client_bytes(m) if self.tlogs else b"")
            if raw:
                for t in self.tlogs.values():
                    t.write(self.clock.unix_us(tick), raw)
            return
        if tgt == 0:
            targets = self.vehicles
        elif tgt in self._by_sysid:
            targets = [self._by_sysid[tgt]]
        else:
            self.counts["unknown_target_system"] += 1
            return
        comp = m.target_component
        if comp not in (None, mav.MAV_COMP_ID_ALL, mav.MAV_COMP_ID_AUTOPILOT1):
            self.counts["other_component"] += 1  # a camera, gimbal, ...: not ours
            return
        raw = m.raw or (self._client_bytes(m) if self.tlogs else b"")
        for v in targets:
            tlog = self.tlogs.get(v.sysid)
            if tlog is not None and raw:
                tlog.write(self.clock.unix_us(tick), raw)
            try:
                out = self.handler.handle(v, m, tick)
            except Exception:
                # a bug, not bad input: log it loudly, keep flying, still answer
                log.exception("mavlink: handling %s for system %d failed", m.name, v.sysid)
                self.counts["handler_errors"] += 1
                out = Outcome()
                if m.name in ("COMMAND_LONG", "COMMAND_INT"):
                    out.replies.append(command_ack(m, int(m.fields["command"]),
                                                   mav.MAV_RESULT_FAILED))
            for name, fields in out.replies:
                try:
                    self._send(v, name, fields, tick, to=sender)
                except ValueError:  # a reply that does not encode: a bug, never a crash
                    log.exception("mavlink: answering %s for system %d failed", m.name,
                                  v.sysid)
                    self.counts["handler_errors"] += 1
            if out.commands:
                origin = _origin(m)
                commands.extend(VehicleCommand(v.row, c, origin) for c in out.commands)
