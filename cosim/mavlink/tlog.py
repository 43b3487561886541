"""Telemetry logs (``.tlog``) in the standard format ground stations write.

Each record is an 8-byte big-endian timestamp in microseconds since the
unix epoch followed by one raw MAVLink packet; pymavlink's
``mavutil.mavlink_connection("x.tlog")``, ``mavlogdump.py``, MAVExplorer
and Mission Planner read them. Timestamps are simulation time anchored to
a past wall-clock instant (``SimClock.unix_us``), so a run's tlogs do not
depend on how fast it ran.

Records are buffered and written with one unbuffered ``write`` at
``flush()`` (the outbox flushes at least every ``TLOG_FLUSH_S`` of wall
time and at close): a hard crash loses at most that much.
"""

from __future__ import annotations

import io
import struct
from pathlib import Path

_STAMP = struct.Struct(">Q")
STAMP_LEN = _STAMP.size


def stamp(unix_us: int) -> bytes:
    """A record's packed timestamp (for ``TlogWriter.write_records``)."""
    return _STAMP.pack(int(unix_us))


class TlogWriter:
    """One vehicle's tlog (both directions)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f: io.FileIO | None = open(self.path, "wb", buffering=0)
        self._buf = bytearray()
        self.records = 0
        self._last_us = 0

    def write(self, unix_us: int, packet: bytes) -> None:
        """Queue one record; timestamps never go backwards within a file."""
        t = max(int(unix_us), self._last_us)
        self.write_records(t, _STAMP.pack(t) + packet, 1)

    def write_records(self, unix_us: int, records: bytes, count: int) -> None:
        """Queue ``count`` whole records (stamp + packet each) all stamped
        ``unix_us`` (not before the last record's time)."""
        if self._f is None:
            raise ValueError(f"tlog {self.path} is closed")
        if unix_us < self._last_us:
            raise ValueError(f"tlog {self.path}: records at {unix_us} us after {self._last_us}")
        self._last_us = unix_us
        self._buf += records
        self.records += count

    def flush(self) -> None:
        if self._buf and self._f is not None:
            view = memoryview(self._buf)
            while view:
                n = self._f.write(view)
                if not n:
                    raise OSError(f"tlog {self.path}: short write")
                view = view[n:]
            self._buf = bytearray()

    @property
    def closed(self) -> bool:
        return self._f is None

    def close(self) -> None:
        """Flush and close (safe to call twice)."""
        if self._f is not None:
            self.flush()
            self._f.close()
            self._f = None
