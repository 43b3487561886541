"""State, event and summary writers (see the package docstring)."""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import shutil
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from cosim.core.geo import LocalFrame
from cosim.core.state import STATE_INDEX

#: the columns of states.parquet, in order
STATE_COLUMNS: tuple[str, ...] = (
    "tick", "time_s", "vehicle", "lat_deg", "lon_deg", "alt_msl_m", "alt_agl_m",
    "north_m", "east_m", "down_m", "roll_deg", "pitch_deg", "yaw_deg",
    "vn_mps", "ve_mps", "vd_mps", "airspeed_mps", "alpha_deg", "throttle",
    "bank_limit_deg", "ap_engaged", "stalled", "stall_protection_active", "command", "status",
)
_FROM_STATE = ("lat_deg", "lon_deg", "alt_msl_m", "alt_agl_m", "roll_deg", "pitch_deg",
               "yaw_deg", "vn_mps", "ve_mps", "vd_mps", "airspeed_mps", "alpha_deg", "throttle",
               "bank_limit_deg", "ap_engaged", "stalled", "stall_protection_active")
_FLAGS = ("ap_engaged", "stalled", "stall_protection_active", "status")
#: the columns that change with every tick of every aircraft: parquet's
#: dictionary encoding of them always overflows (all values differ), so parts
#: try it only on the others (tick, vehicle, command, the flags, ...); a part
#: of 25 ticks of 2048 aircraft then takes 40 % less CPU to write and is 30 %
#: smaller, the values the same
_NO_DICTIONARY = frozenset((
    "lat_deg", "lon_deg", "alt_msl_m", "alt_agl_m", "north_m", "east_m", "down_m",
    "roll_deg", "pitch_deg", "yaw_deg", "vn_mps", "ve_mps", "vd_mps", "airspeed_mps",
    "alpha_deg", "throttle"))


def write_part(table: pa.Table, where: str | Path | IO[bytes]) -> None:
    """Write ``table`` as one part of ``states.parquet`` (zstd)."""
    pq.write_table(table, where, compression="zstd",
                   use_dictionary=[c for c in table.schema.names if c not in _NO_DICTIONARY])


def state_schema(extra: Sequence[str] = ()) -> pa.Schema:
    """The columns of states.parquet: ``STATE_COLUMNS``, then (float64) the
    columns the run's vehicle classes add."""
    fields = []
    for c in STATE_COLUMNS:
        if c == "tick":
            fields.append(pa.field(c, pa.int64()))
        elif c in ("vehicle", "command"):
            fields.append(pa.field(c, pa.dictionary(pa.int32(), pa.string())))
        elif c in _FLAGS:
            fields.append(pa.field(c, pa.int8()))
        else:
            fields.append(pa.field(c, pa.float64()))
    fields += [pa.field(c, pa.float64()) for c in extra]
    return pa.schema(fields)


class StateLog:
    """Writes logged ticks as complete parquet parts, journalling each tick first.

    Every logged tick becomes one record batch, appended (unbuffered) to an
    Arrow IPC stream ``_journal-NNNNNN.arrows`` beside the parts: a driver
    killed between parts loses at most the tick being written. A part
    ``part-NNNNNN.parquet`` is written (to a hidden temporary file, renamed
    into place) when ``flush_rows`` rows are buffered or ``flush_s`` seconds
    of wall time have passed since the last part, and on ``close``; its
    journal is deleted once it is in place. The leading ``_`` keeps journals
    out of the dataset that pyarrow and pandas read from the folder;
    ``read_states`` reads them too.

    A failed write (a full disk) raises one ``OSError`` naming the file and
    leaves everything readable: a journal append that fails is cut back to
    its last complete record batch (and journalling stops), a part that
    fails leaves no temporary file and keeps its ticks buffered and
    journalled. ``failed`` holds that first error; later appends only buffer,
    and ``close`` tries once more to write the part (the run frees its disk
    reserve first) without raising the same failure again. ``complete`` says
    whether every logged tick is in a part. ``cosim recover`` turns what a
    killed or failed run left into parts.
    """

    def __init__(self, folder: Path, ids: list[str], frame: LocalFrame, physics_hz: float,
                 flush_rows: int = 200_000, flush_s: float = 5.0,
                 extra: Sequence[tuple[str, int]] = ()) -> None:
        self.dir = Path(folder)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.ids = pa.array(ids, pa.string())
        self.n = len(ids)
        self.frame = frame
        self.physics_hz = physics_hz
        self.flush_rows = flush_rows
        self.flush_s = flush_s
        #: the columns vehicle classes add: (name, state column), logged after ``status``
        self.extra = list(extra)
        self.schema = state_schema([name for name, _ in self.extra])
        self._batches: list[pa.RecordBatch] = []
        self._vehicle = pa.DictionaryArray.from_arrays(
            pa.array(np.arange(self.n, dtype=np.int32)), self.ids)
        self._journal: Any = None  # pa.ipc.RecordBatchStreamWriter
        self._journal_file: Any = None
        self._parts = 0
        self._last_flush = time.monotonic()
        self.rows_logged = 0  # rows appended (in parts or journalled)
        self.last_tick: int | None = None
        self._cols = [STATE_INDEX[c] for c in _FROM_STATE]
        self._closed = False
        self.failed: OSError | None = None  # the first failed write
        self._journal_ok = 0  # bytes of the journal known to hold complete batches

    def _batch(self, tick: int, states: np.ndarray, commands: list[str] | None) -> pa.RecordBatch:
        block = states[:, self._cols]  # a copy (fancy indexing)
        cols: dict[str, Any] = {"tick": np.full(self.n, tick, dtype=np.int64)}
        cols["time_s"] = cols["tick"] / self.physics_hz
        cols["vehicle"] = self._vehicle
        for j, name in enumerate(_FROM_STATE):
            cols[name] = block[:, j]
        north, east, down = self.frame.geodetic_to_ned(cols["lat_deg"], cols["lon_deg"],
                                                        cols["alt_msl_m"])
        cols["north_m"], cols["east_m"], cols["down_m"] = north, east, down
        for c in _FLAGS[:-1]:
            cols[c] = cols[c].astype(np.int8)
        cols["status"] = states[:, STATE_INDEX["status"]].astype(np.int8)
        labels = commands if commands is not None else [""] * self.n
        cols["command"] = pa.array(labels, pa.string()).dictionary_encode()
        for name, j in self.extra:
            cols[name] = states[:, j].copy()
        return pa.RecordBatch.from_arrays([cols[c] for c in self.schema.names],
                                          schema=self.schema)

    def append(self, tick: int, states: np.ndarray, commands: list[str] | None = None) -> None:
        """Log one tick (journalled at once); ``commands``: each vehicle's
        active command, for the ``command`` column."""
        batch = self._batch(tick, states, commands)
        self._batches.append(batch)
        self.rows_logged += self.n
        self.last_tick = tick
        if self.failed is not None:  # after a failure: kept for close() to try once more
            return
        self._journal_append(batch)
        buffered = len(self._batches) * self.n
        if buffered >= self.flush_rows or time.monotonic() - self._last_flush >= self.flush_s:
            self.flush()

    def _journal_append(self, batch: pa.RecordBatch) -> None:
        path = self._journal_path(self._parts)
        try:
            if self._journal is None:
                self._journal_file = open(path, "wb", buffering=0)  # noqa: SIM115
                self._journal = pa.ipc.new_stream(self._journal_file, self.schema)
                self._journal_ok = self._journal_file.tell()
            self._journal.write_batch(batch)
            self._journal_ok = self._journal_file.tell()
        except OSError as e:
            self._abandon_journal()
            self._fail(e, path)

    def _abandon_journal(self) -> None:
        """Stop journalling: cut the journal back to its last complete batch
        (a write cut short leaves a partial one) and close it."""
        f, self._journal_file, self._journal = self._journal_file, None, None
        if f is None:
            return
        try:
            os.ftruncate(f.fileno(), self._journal_ok)
        except OSError:
            pass
        finally:
            try:
                f.close()  # the writer is dropped unclosed: no end-of-stream marker
            except OSError:
                pass

    def _fail(self, e: OSError, path: Path) -> None:
        err = OSError(e.errno, f"cannot write {path}: {e.strerror or e}")
        if self.failed is None:
            self.failed = err
        raise err from e

    @property
    def complete(self) -> bool:
        """Every logged tick is in a part (closed without a failure left over)."""
        return self._closed and not self._batches

    def _journal_path(self, part: int) -> Path:
        return self.dir / f"_journal-{part:06d}.arrows"

    def _close_journal(self) -> None:
        try:
            if self._journal is not None:
                self._journal.close()
        finally:
            self._journal = None
            if self._journal_file is not None:
                self._journal_file.close()
                self._journal_file = None

    def flush(self) -> None:
        """Write the buffered ticks as the next part, then delete their journal.
        On failure (``OSError`` naming the file) nothing is lost: the ticks stay
        buffered and journalled, and the next flush tries again."""
        if not self._batches:
            return
        table = pa.Table.from_batches(self._batches, self.schema)
        table = table.unify_dictionaries().combine_chunks()
        final = self.dir / f"part-{self._parts:06d}.parquet"
        tmp = self.dir / f".{final.name}.tmp"
        try:
            write_part(table, tmp)
            os.replace(tmp, final)
        except OSError as e:
            tmp.unlink(missing_ok=True)
            self._fail(e, final)
        self._close_journal()
        self._journal_path(self._parts).unlink(missing_ok=True)
        self._parts += 1
        self._batches = []
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Write the last part. If that fails the journal stays on disk (and
        ``read_states`` reads it); the error is raised, unless it repeats an
        earlier failure (``failed``): one failure, one error."""
        if self._closed:
            return
        self._closed = True
        earlier = self.failed
        try:
            self.flush()
        except OSError:
            if earlier is None:
                raise
        finally:
            if self._journal is not None:
                try:
                    self._close_journal()
                except OSError:  # the end-of-stream marker did not fit: the batches did
                    self._abandon_journal()


#: what a run writes into its output folder (``clear_outputs`` removes them)
RUN_OUTPUTS = ("states.parquet", "events.jsonl", "summary.json", "scenario.resolved.yaml",
               "commands.jsonl", "track.png", "faulthandler.log", ".cosim-reserve",
               ".cosim-reserve-summary")


def clear_outputs(folder: str | Path) -> None:
    """Remove a previous run's outputs from ``folder`` so that a new run starts
    from empty ones (its other files are left alone)."""
    out = Path(folder)
    for name in RUN_OUTPUTS:
        p = out / name
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)
        Path(str(p) + ".tmp").unlink(missing_ok=True)


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, (np.floating, np.integer)):
        return _jsonable(v.item())
    return v


class EventLog:
    """``events.jsonl``: one object per line, written and flushed as it happens.

    ``emit`` never raises: a line that cannot be written (a full disk) is kept
    (at most ``MAX_PENDING`` of them) and written before the next one, or at
    ``close``; what still cannot be written is counted in ``dropped``. Each
    line is written whole or not at all (a partial line is cut back)."""

    MAX_PENDING = 10_000

    def __init__(self, path: Path, physics_hz: float) -> None:
        self.path = Path(path)
        self.physics_hz = physics_hz
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        self.counts: dict[str, int] = {}
        self._pending: list[bytes] = []
        self.dropped = 0
        self.failed: OSError | None = None  # the latest failed write

    def emit(self, kind: str, tick: int, vehicle: str | None = None, **fields: Any) -> None:
        rec = {"event": kind, "tick": tick, "time_s": tick / self.physics_hz,
               "vehicle": vehicle}
        rec.update({k: _jsonable(v) for k, v in fields.items()})
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if len(self._pending) >= self.MAX_PENDING:
            self.dropped += 1
            return
        self._pending.append((json.dumps(rec) + "\n").encode())
        self._write_pending()

    def _write_pending(self) -> None:
        while self._pending and self._fd >= 0:
            line = self._pending[0]
            try:
                size = os.lseek(self._fd, 0, os.SEEK_END)
                done = os.write(self._fd, line)
                if done != len(line):  # cut short: take it back, try again later
                    os.ftruncate(self._fd, size)
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            except OSError as e:
                self.failed = OSError(e.errno, f"cannot write {self.path}: {e.strerror or e}")
                return
            self._pending.pop(0)
            self.failed = None

    @property
    def complete(self) -> bool:
        """Every event emitted is in the file."""
        return not self._pending and not self.dropped

    def close(self) -> None:
        if self._fd < 0:
            return
        self._write_pending()
        self.dropped += len(self._pending)
        self._pending.clear()
        os.close(self._fd)
        self._fd = -1


@contextlib.contextmanager
def replacing(path: str | Path, mode: str = "w", tmp: str | Path | None = None
              ) -> Iterator[IO[Any]]:
    """A new file to write ``path``'s content into: ``tmp`` (default
    ``PATH.tmp``), created afresh (a stale one, or a symlink left in its
    place, is removed, never followed) and renamed over ``path`` when the
    block ends, so ``path`` is replaced whole or not at all (a symlink at
    ``path`` is replaced, not written through). A failure removes the
    temporary file and is an ``OSError`` naming ``path``."""
    path = Path(path)
    tmp = Path(tmp) if tmp is not None else Path(str(path) + ".tmp")
    try:
        tmp.unlink(missing_ok=True)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        with os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8") as f:
            yield f
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OSError(e.errno, f"cannot write {path}: {e.strerror or e}") from e
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_json_atomic(path: Path, data: Any) -> None:
    """Replace ``path`` with ``data`` as JSON, whole or not at all: a failed
    write (``OSError`` naming the file) leaves the old file and no ``.tmp``."""
    with replacing(path) as f:
        f.write(json.dumps(data, indent=2, default=_jsonable) + "\n")
        f.flush()
        os.fsync(f.fileno())


class DiskReserve:
    """A file of ``size`` bytes kept in a run folder so that the run's last
    writes (closing videos and logs, the summary) find room on a full disk:
    ``release()`` deletes it just before they are made."""

    def __init__(self, path: Path, size: int) -> None:
        self.path = Path(path)
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                if hasattr(os, "posix_fallocate"):
                    os.posix_fallocate(fd, 0, size)  # real blocks, not a sparse file
                else:
                    os.write(fd, bytes(size))
            finally:
                os.close(fd)
            self.held = size
        except OSError:  # no room even for it: nothing held
            self.path.unlink(missing_ok=True)
            self.held = 0

    def release(self) -> None:
        self.path.unlink(missing_ok=True)
        self.held = 0
