"""Batch encoding: one MAVLink 2 message type for many vehicles at once.

Telemetry is the bulk of what the endpoint sends (at default rates about 17
packets per vehicle per second), and encoding packets one at a time through
pymavlink costs tens of microseconds each. ``BatchEncoder`` lays the
payloads of all due vehicles out in one numpy structured array (the wire
order and types pymavlink's dialect defines, via ``adapter.wire_layout``),
truncates trailing zero bytes as MAVLink 2 requires, and computes every
packet's CRC-16/MCRF4XX (the X.25 CRC MAVLink uses) column by column over
all packets at once. The packets are byte-for-byte those pymavlink would
produce (tested against it). Unsigned only: with signing on the endpoint
packs one packet at a time through pymavlink.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from cosim.mavlink import adapter as mav

_STX_V2 = 0xFD
_HEADER_LEN = 10  # STX, len, incompat, compat, seq, sysid, compid, msgid (3 bytes)


def _crc_table() -> np.ndarray:
    """CRC-16/MCRF4XX (reflected polynomial 0x8408) byte table."""
    table = np.zeros(256, dtype=np.uint16)
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
        table[i] = crc
    return table


_TABLE = _crc_table()
_CRC = mav.crc16_mcrf4xx


class BatchEncoder:
    """Encodes one message type for many senders at once."""

    def __init__(self, name: str, component_id: int = mav.MAV_COMP_ID_AUTOPILOT1) -> None:
        self.name = name
        self.msgid, self.crc_extra, layout = mav.wire_layout(name)
        self.dtype = np.dtype([(f, t, (n,)) if n else (f, t) for f, t, n in layout])
        self.field_names = tuple(f for f, _, _ in layout)
        self.payload_len = self.dtype.itemsize
        self.component_id = component_id

    def payloads(self, n: int, columns: Mapping[str, Any]) -> np.ndarray:
        """The (n,) structured array of payloads; omitted fields are 0, values
        are cast to the wire types (callers give integers already rounded and
        in range, as pymavlink requires)."""
        rec = np.zeros(n, dtype=self.dtype)
        for k, v in columns.items():
            rec[k] = v
        return rec

    def encode(self, rec: np.ndarray, sysid: np.ndarray, seq: np.ndarray
               ) -> tuple[bytes, np.ndarray]:
        """All packets, concatenated in row order, and each packet's length."""
        n = len(rec)
        body = rec.view(np.uint8).reshape(n, self.payload_len)
        # MAVLink 2 drops trailing zero bytes of the payload (at least one byte stays)
        nz = body != 0
        last = self.payload_len - np.argmax(nz[:, ::-1], axis=1)
        plen = np.where(nz.any(axis=1), last, 1).astype(np.intp)
        width = _HEADER_LEN + self.payload_len + 2
        buf = np.zeros((n, width), dtype=np.uint8)
        buf[:, 0] = _STX_V2
        buf[:, 1] = plen
        buf[:, 4] = seq
        buf[:, 5] = sysid
        buf[:, 6] = self.component_id
        buf[:, 7] = self.msgid & 0xFF
        buf[:, 8] = (self.msgid >> 8) & 0xFF
        buf[:, 9] = self.msgid >> 16
        buf[:, _HEADER_LEN:_HEADER_LEN + self.payload_len] = body
        rows = np.arange(n)
        end = _HEADER_LEN + plen  # where each packet's payload ends
        if _CRC is not None:  # C, one call per packet
            raw = buf.tobytes()
            extra = bytes([self.crc_extra])
            crcs = [_CRC(extra, _CRC(raw[i * width + 1:i * width + e], 0xFFFF))
                    for i, e in enumerate(end.tolist())]
            crc = np.array(crcs, dtype=np.uint16)
        else:
            crc = _crc_numpy(buf, end, self.crc_extra)
        buf[rows, end] = crc & 0xFF
        buf[rows, end + 1] = crc >> 8
        total = end + 2
        keep = np.arange(width)[None, :] < total[:, None]
        return buf[keep].tobytes(), total


def _crc_numpy(buf: np.ndarray, end: np.ndarray, crc_extra: int) -> np.ndarray:
    """The CRC of every row, column by column (without fastcrc): bytes 1 up to
    each row's ``end``, then ``crc_extra``."""
    crc = np.full(len(buf), 0xFFFF, dtype=np.uint16)
    cols = buf.T  # column j: byte j of every packet
    shortest = int(end.min())
    for j in range(1, shortest):  # bytes every packet has
        crc = (crc >> 8) ^ _TABLE[(crc ^ cols[j]) & 0xFF]
    for j in range(shortest, int(end.max())):  # only packets this long
        new = (crc >> 8) ^ _TABLE[(crc ^ cols[j]) & 0xFF]
        crc = np.where(j < end, new, crc)
    return (crc >> 8) ^ _TABLE[(crc ^ crc_extra) & 0xFF]
