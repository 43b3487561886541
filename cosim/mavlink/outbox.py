"""Where everything an endpoint's vehicles send goes: the link (its peers, and
the sender of the message answered), the in-process subscribers (each
packet as the ``Message`` a receiver decodes) and each vehicle's tlog,
which also keeps every message the vehicle received. One sequence number
per vehicle, whether a packet goes alone (``send``: packed, and signed when
signing is on, by the vehicle's packer) or in a telemetry batch
(``send_batch``, encoded by ``cosim.mavlink.telemetry``)."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from cosim.mavlink import adapter as mav
from cosim.mavlink.link import NullLink, UdpLink
from cosim.mavlink.tlog import STAMP_LEN, TlogWriter, stamp
from cosim.mavlink.vehicle import MavVehicle, SimClock, safe_name

#: tlogs are written to disk at most this often (wall clock) and at close:
#: a hard crash loses at most this much of them
TLOG_FLUSH_S = 0.5


class Outbox:
    """The outgoing side of one endpoint (see the module docstring);
    ``signing``: whether the vehicles' packers sign (their signature
    timestamps then follow the wall clock)."""

    def __init__(self, vehicles: Sequence[MavVehicle], clock: SimClock,
                 link: UdpLink | NullLink, counts: Counter[str], signing: bool) -> None:
        self.vehicles = vehicles
        self.clock = clock
        self.link = link
        self.counts = counts
        self.signing = signing
        #: each vehicle's next sequence number (the batches and its packer share it)
        self.seq = np.zeros(len(vehicles), dtype=np.int64)
        #: in-process clients: called with every packet sent, in sending order
        self.subscribers: list[Callable[[mav.Message], None]] = []
        #: each vehicle's tlog, by system id
        self.tlogs: dict[int, TlogWriter] = {}
        #: encoders of in-process clients' messages for the tlogs, by (system, component)
        self._client_packers: dict[tuple[int, int], mav.Packer] = {}
        self._tlog_flushed = time.monotonic()

    def open_tlogs(self, folder: str | Path) -> None:
        """One ``<vehicle name>.tlog`` per vehicle in ``folder`` (a name two
        vehicles share gets ``-sys<system id>``)."""
        used: set[str] = set()
        for v in self.vehicles:
            stem = safe_name(v.spec.name)
            if stem in used:
                stem = f"{stem}-sys{v.sysid}"
            used.add(stem)
            self.tlogs[v.sysid] = TlogWriter(Path(folder) / f"{stem}.tlog")

    def send(self, v: MavVehicle, name: str, fields: Mapping[str, object], tick: int,
             to: tuple[str, int] | None = None) -> None:
        """Send one message from ``v`` to the peers (and ``to``: the sender of
        the message it answers)."""
        if self.signing:
            v.packer.advance_signing_time(mav.wall_signing_timestamp())
        v.packer.seq = int(self.seq[v.index])  # one sequence per vehicle, batches included
        pkt = v.packer.pack(name, **fields)
        self.seq[v.index] = v.packer.seq
        self.link.send(pkt, also=to)
        if self.subscribers:
            m = mav.Message(name, v.sysid, mav.MAV_COMP_ID_AUTOPILOT1,
                            mav.wire_values(name, dict(fields)))
            for cb in self.subscribers:
                cb(m)
        self.counts["packets_out"] += 1
        t = self.tlogs.get(v.sysid)
        if t is not None:
            t.write(self.clock.unix_us(tick), pkt)

    def deliver(self, name: str, field_names: Sequence[str], vs: Sequence[MavVehicle],
                records: list[tuple[object, ...]]) -> None:
        """A batch's messages (one record of field values per vehicle) to the
        subscribers."""
        for v, values in zip(vs, records):
            m = mav.Message(name, v.sysid, mav.MAV_COMP_ID_AUTOPILOT1,
                            dict(zip(field_names, values)))
            for cb in self.subscribers:
                cb(m)

    def send_batch(self, blob: bytes, lens: np.ndarray, who: np.ndarray, unix_us: int) -> None:
        """An exchange's batched packets (``blob``, packets of ``lens`` bytes
        each, from vehicle index ``who`` each) to the peers and the tlogs."""
        self.link.send_packets(blob, lens.tolist())
        if self.tlogs:
            self._tlog_batch(blob, lens, who, unix_us)

    def _tlog_batch(self, blob: bytes, lens: np.ndarray, who: np.ndarray, unix_us: int) -> None:
        """The records (stamp + packet) laid out per vehicle in one numpy pass,
        then each tlog takes its run of records at once."""
        order = np.argsort(who, kind="stable")  # per vehicle, in sending order
        src_start = np.cumsum(lens) - lens
        n_sorted = lens[order]
        rec_len = n_sorted + STAMP_LEN
        dst_start = np.cumsum(rec_len) - rec_len
        out = np.empty(int(rec_len.sum()), dtype=np.uint8)
        out[(dst_start[:, None] + np.arange(STAMP_LEN)).ravel()] = np.tile(
            np.frombuffer(stamp(unix_us), dtype=np.uint8), len(order))
        total = int(n_sorted.sum())
        within = np.arange(total) - np.repeat(np.cumsum(n_sorted) - n_sorted, n_sorted)
        out[np.repeat(dst_start + STAMP_LEN, n_sorted) + within] = np.frombuffer(
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

    # -- what the vehicles received ---------------------------------------------
    def received_bytes(self, m: mav.Message) -> bytes:
        """The packet ``m`` was on the network, or would have been (an
        in-process client's message), for the tlogs: they hold what the
        vehicle received, whoever sent it (b"": no tlogs, or it does not
        encode)."""
        if m.raw:
            return m.raw
        if not self.tlogs:
            return b""
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

    def log_received(self, raw: bytes, tick: int, sysid: int | None = None) -> None:
        """A received packet into the tlog of vehicle ``sysid`` (None: every
        vehicle's)."""
        if not raw:
            return
        if sysid is None:
            for t in self.tlogs.values():
                t.write(self.clock.unix_us(tick), raw)
            return
        mine = self.tlogs.get(sysid)
        if mine is not None:
            mine.write(self.clock.unix_us(tick), raw)

    # -- lifecycle ---------------------------------------------------------------
    def flush(self) -> None:
        """Write the tlogs to disk if ``TLOG_FLUSH_S`` has passed since the last time."""
        now = time.monotonic()
        if now - self._tlog_flushed >= TLOG_FLUSH_S:
            self._tlog_flushed = now
            for t in self.tlogs.values():
                t.flush()

    def close_tlogs(self) -> None:
        for t in self.tlogs.values():
            t.close()

    @property
    def tlog_records(self) -> int:
        return sum(t.records for t in self.tlogs.values())
