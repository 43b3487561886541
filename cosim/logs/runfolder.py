"""A run folder read as untrusted input.

Run folders travel (copied, downloaded, made by another version of cosim, cut
short by a crash or a full disk), so every command that reads one (``cosim
export``, ``recover``, ``plot``, ``visibility`` and a sweep's tables) reads it
here, bounded:

- a file is opened only if it is a regular file whose path, symlinks
  followed, stays inside the run folder: a symlink to ``/dev/zero`` or out of
  the folder, a FIFO, a folder where a file belongs are refused before a
  byte is read; and only up to its limit (``MAX_*_BYTES``);
- ``scenario.resolved.yaml`` is read and checked field by field by
  ``cosim.logs.resolved``; JSON is nested at most ``MAX_DEPTH`` levels; an
  ``events.jsonl`` line holds at most ``MAX_LINE_BYTES``;
- states: at most ``MAX_STATE_ROWS`` rows in at most ``MAX_STATE_FILES``
  files (a part's rows counted from its footer before it is read), the
  columns a command needs present and of their type, and every value read
  in range (``state_range``; NaN, "not known", is allowed except in ``tick``
  and ``time_s``).

A problem is a ``ConfigError`` (exit 2) naming the file with its line or
row, and what was expected. Nothing here writes.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from cosim.core.limits import (
    MAX_DEPTH,
    MAX_DURATION_S,
    MAX_NAME_CHARS,
    MAX_NUMBER,
    MIN_EXCHANGE_HZ,
    PHYSICS_HZ_RANGE,
)
from cosim.errors import ConfigError
from cosim.logs.resolved import RESOLVED, Resolved, is_number, read_resolved, show_value
from cosim.logs.writers import state_schema
from cosim.scenario.yaml_lines import open_bounded, read_bounded, read_text_bounded

#: ``summary.json``, ``sweep.json``
MAX_JSON_BYTES = 16 * 1024 * 1024
#: ``events.jsonl`` and one line of it
MAX_EVENTS_BYTES = 1024 ** 3
MAX_LINE_BYTES = 1024 * 1024
#: a camera's ground-truth CSV (about 200 bytes a frame and target: an hour
#: at 30 Hz with 10 targets takes 220 MB)
MAX_GROUND_TRUTH_BYTES = 1024 ** 3
#: one Parquet part or journal of ``states.parquet/``, the files of one run
#: (a part at least every 5 s of wall time: a 30-day run writes 518,400),
#: and the rows of all of them (10,000 vehicles logged at 10 Hz for 1000 s;
#: read bigger runs part by part with pyarrow)
MAX_STATE_FILE_BYTES = 4 * 1024 ** 3
MAX_STATE_FILES = 1_000_000
MAX_STATE_ROWS = 100_000_000
#: the last exchange of a run may end up to one exchange past its duration
MAX_TIME_S = MAX_DURATION_S + 1.0 / MIN_EXCHANGE_HZ
MAX_TICK = int(MAX_TIME_S * PHYSICS_HZ_RANGE[1])

_TEXT_COLUMNS = ("vehicle", "command")


def state_range(column: str) -> tuple[float, float, bool]:
    """(lowest, highest, NaN allowed) for a value of a states column."""
    if column == "tick":
        return 0, MAX_TICK, False
    if column == "time_s":
        return 0.0, MAX_TIME_S, False
    if column == "lat_deg":
        return -90.0, 90.0, True
    if column == "lon_deg":
        return -180.0, 180.0, True
    return -MAX_NUMBER, MAX_NUMBER, True


def parse_json(text: str | bytes, where: str, line: int | None = None) -> Any:
    """A JSON value nested at most ``MAX_DEPTH`` levels; ``ConfigError``
    naming ``where`` (and the line: ``line``, else the error's) otherwise."""
    at = f"{where}:{line}" if line is not None else where
    try:
        value = json.loads(text)
    except RecursionError:
        raise ConfigError(f"{at}: nested more than {MAX_DEPTH} levels deep") from None
    except json.JSONDecodeError as e:
        at = at if line is not None else f"{where}:{e.lineno}"
        raise ConfigError(f"{at}: not JSON: {e.msg} (column {e.colno})") from None
    except ValueError as e:  # not UTF-8, a number of thousands of digits
        raise ConfigError(f"{at}: not JSON: {e}") from None
    stack = [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, (dict, list)):
            if depth > MAX_DEPTH:
                raise ConfigError(f"{at}: nested more than {MAX_DEPTH} levels deep")
            stack.extend((x, depth + 1) for x in (v.values() if isinstance(v, dict) else v))
    return value


def physics_hz(d: dict[str, Any]) -> float | None:
    """``d``'s ``physics_hz`` (a summary's) if it is a physics rate cosim runs at."""
    hz = d.get("physics_hz")
    if is_number(hz) and PHYSICS_HZ_RANGE[0] <= hz <= PHYSICS_HZ_RANGE[1]:
        return float(hz)
    return None


@dataclass(frozen=True)
class Event:
    """One line of ``events.jsonl``: its kind, tick, vehicle and all its fields."""

    kind: str
    tick: int
    vehicle: str | None
    fields: dict[str, Any]


class RunFolder:
    """A run folder (``path``, as given) whose files are read bounded and
    only inside it (see the module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self.root = self.path.resolve(strict=True)
        except (OSError, RuntimeError):
            raise ConfigError(f"{self.path}: no such folder") from None
        if not self.root.is_dir():
            raise ConfigError(f"{self.path}: not a folder")

    def has(self, name: str | Path) -> bool:
        """Something (a file, a folder, a symlink, even a broken one) is at ``name``."""
        p = self.path / name
        return p.is_symlink() or p.exists()

    def file(self, name: str | Path) -> Path:
        """``name``'s path in the folder (as given, for messages), once it is
        sure that it stays inside the folder with its symlinks followed."""
        p = self.path / name
        try:
            real = p.resolve()
        except (OSError, RuntimeError) as e:  # a symlink loop
            raise ConfigError(f"{p}: cannot read: {e}") from None
        if real != self.root and self.root not in real.parents:
            raise ConfigError(f"{p}: leads outside the run folder (to {real}); a run's "
                              f"files are read only inside its folder")
        return p

    def text(self, name: str | Path, limit: int, what: str) -> str:
        return read_text_bounded(self.file(name), limit, what, f"a {what} file")

    def json(self, name: str | Path, limit: int = MAX_JSON_BYTES) -> Any:
        p = self.file(name)
        return parse_json(read_text_bounded(p, limit, "JSON", f"a {p.name}"), str(p))

    def summary(self) -> dict[str, Any] | None:
        """``summary.json`` (None: there is none)."""
        if not self.has("summary.json"):
            return None
        s = self.json("summary.json")
        if not isinstance(s, dict):
            raise ConfigError(f"{self.path / 'summary.json'}: expected a JSON object, got "
                              f"{type(s).__name__}")
        return s

    # -- events.jsonl -----------------------------------------------------------------
    def json_lines(self, name: str = "events.jsonl") -> Iterator[tuple[int, bytes]]:
        """(line number, text) of every whole line (an unterminated last one,
        from a run killed while writing it, is left out)."""
        p = self.file(name)
        with open_bounded(p, MAX_EVENTS_BYTES, "events", "an events file") as f:
            for n, line in enumerate(iter(lambda: f.readline(MAX_LINE_BYTES + 1), b""), 1):
                if len(line) > MAX_LINE_BYTES:
                    raise ConfigError(f"{p}:{n}: a line of more than {MAX_LINE_BYTES} bytes")
                if not line.endswith(b"\n"):
                    return
                yield n, line

    def events(self, skipped: list[str] | None = None) -> Iterator[Event]:
        """The events of ``events.jsonl`` (none if there is none). A line that
        is not an event is a ``ConfigError``, or, with ``skipped``, is
        appended there (the message) and left out."""
        if not self.has("events.jsonl"):
            return
        where = str(self.path / "events.jsonl")
        for n, line in self.json_lines():
            try:
                yield _event(parse_json(line, where, n), f"{where}:{n}")
            except ConfigError as e:
                if skipped is None:
                    raise
                skipped.append(str(e))

    def resolved(self) -> Resolved | None:
        """The run's resolved scenario (None: there is none), checked
        (``cosim.logs.resolved``)."""
        if not self.has(RESOLVED):
            return None
        return read_resolved(self.file(RESOLVED), self.path.name)

    # -- states.parquet -------------------------------------------------------------------
    def states(self, columns: Sequence[str] | None = None, name: str = "states.parquet"
               ) -> pa.Table:
        """``states.parquet`` (a parts folder, or one file; ``name``) as one
        table in tick order, only ``columns`` (all when None): every part,
        then the ticks journalled but not in a part (a run that crashed or
        could not write its last part). Bounded and checked (module docstring)."""
        if not self.has(name):
            raise ConfigError(f"{self.path}: not a cosim run folder (no {name})")
        states = self.file(name)
        if not states.is_dir():
            return self._checked(self._part(states, columns), states, columns)
        parts, journals = state_files(states)
        if len(parts) + len(journals) > MAX_STATE_FILES:
            raise ConfigError(f"{states}: {len(parts) + len(journals)} files; a run's states "
                              f"may have at most {MAX_STATE_FILES}")
        parts = [self.file(x.relative_to(self.path)) for x in parts]
        journals = [self.file(j.relative_to(self.path)) for j in journals]
        schema = stored_schema(parts, journals)
        tables, rows = [], 0
        for x in parts:
            t = self._part(x, columns, schema, rows)
            rows += t.num_rows
            tables.append(self._checked(t, x, columns))
        for j in journals:
            batches = journal_batches(j)[0]
            rows += sum(b.num_rows for b in batches)
            _check_rows(j, rows)
            if batches:
                try:
                    t = pa.Table.from_batches(batches, schema)
                except (pa.ArrowException, ValueError) as e:
                    raise ConfigError(f"{j}: not the columns of the run's other states "
                                      f"files: {e}") from None
                tables.append(self._checked(t.select(_columns(t.schema, columns, j)), j,
                                            columns))
        if not tables:
            return _select(schema, columns, states).empty_table()
        try:
            table = pa.concat_tables(tables)
        except (pa.ArrowException, ValueError) as e:
            raise ConfigError(f"{states}: its files hold different columns: {e}") from None
        if "tick" in table.column_names:
            ticks = table["tick"].to_numpy()
            if ticks.size and (np.diff(ticks) < 0).any():
                table = table.take(pc.sort_indices(table, sort_keys=[("tick", "ascending")]))
        return table

    def _part(self, path: Path, columns: Sequence[str] | None,
              schema: pa.Schema | None = None, before: int = 0) -> pa.Table:
        """One Parquet file's ``columns``, its rows (``before`` of them
        already read) counted from its footer first."""
        with open_bounded(path, MAX_STATE_FILE_BYTES, "states", "a states file") as f:
            try:
                pf = pq.ParquetFile(f)
                _check_rows(path, before + pf.metadata.num_rows)
                stored = pf.schema_arrow
                cols = _columns(stored if schema is None else schema, columns, path)
                missing = [c for c in cols if c not in stored.names]
                if missing:
                    raise ConfigError(f"{path}: no column {missing[0]!r} (the run's first "
                                      f"states file has it)")
                t = pf.read(columns=cols)
                if schema is not None:
                    t = t.cast(_select(schema, cols, path))
                return t
            except (pa.ArrowException, ValueError, TypeError) as e:
                raise ConfigError(f"{path}: cannot read states: {e}") from None

    def _checked(self, table: pa.Table, path: Path, columns: Sequence[str] | None
                 ) -> pa.Table:
        """``table`` if its values are in range; ``ConfigError`` naming the row."""
        for name in table.column_names:
            col = table[name]
            typ = col.type.value_type if pa.types.is_dictionary(col.type) else col.type
            if name in _TEXT_COLUMNS:
                if not (pa.types.is_string(typ) or pa.types.is_large_string(typ)):
                    raise ConfigError(f"{path}: column {name}: expected text, got {col.type}")
                if col.null_count:
                    row = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
                    raise ConfigError(f"{path}: row {row + 1}: {name} is empty")
                continue
            if not (pa.types.is_integer(typ) or pa.types.is_floating(typ)
                    or pa.types.is_boolean(typ)):
                if columns is None:
                    continue  # a column no command reads
                raise ConfigError(f"{path}: column {name}: expected numbers, got {col.type}")
            a = col.to_numpy(zero_copy_only=False).astype(float)
            lo, hi, nan_ok = state_range(name)
            bad = ~((a >= lo) & (a <= hi))
            if nan_ok:
                bad &= ~np.isnan(a)
            if bad.any():
                row = int(np.flatnonzero(bad)[0])
                raise ConfigError(f"{path}: row {row + 1}: {name} is {a[row]:.10g}; expected "
                                  f"{lo:.10g} to {hi:.10g}{' (or NaN)' if nan_ok else ''}")
        if "vehicle" in table.column_names:
            for chunk in table["vehicle"].chunks:
                ids = chunk.dictionary if pa.types.is_dictionary(chunk.type) else chunk
                longest = pc.max(pc.utf8_length(ids)).as_py() if len(ids) else 0
                if longest and longest > MAX_NAME_CHARS:
                    raise ConfigError(f"{path}: a vehicle id of {longest} characters; ids "
                                      f"have at most {MAX_NAME_CHARS}")
        return table


def _check_rows(path: Path, rows: int) -> None:
    if rows > MAX_STATE_ROWS:
        raise ConfigError(f"{path}: the run's states hold more than {MAX_STATE_ROWS} rows "
                          f"up to this file; read a run that big part by part with pyarrow")


def _columns(schema: pa.Schema, columns: Sequence[str] | None, path: Path) -> list[str]:
    if columns is None:
        return list(schema.names)
    missing = [c for c in columns if c not in schema.names]
    if missing:
        raise ConfigError(f"{path}: no column {', '.join(map(repr, missing))} (this command "
                          f"reads {', '.join(columns)})")
    return list(columns)


def _select(schema: pa.Schema, columns: Sequence[str] | None, path: Path) -> pa.Schema:
    return pa.schema([schema.field(c) for c in _columns(schema, columns, path)])


def _event(e: Any, where: str) -> Event:
    if not isinstance(e, dict):
        raise ConfigError(f"{where}: expected an event (a JSON object), got {show_value(e)}")
    kind, tick, vehicle = e.get("event"), e.get("tick"), e.get("vehicle")
    if not (isinstance(kind, str) and 0 < len(kind) <= MAX_NAME_CHARS):
        raise ConfigError(f"{where}: event: expected a name of 1 to {MAX_NAME_CHARS} "
                          f"characters, got {show_value(kind)}")
    if not (isinstance(tick, int) and not isinstance(tick, bool) and 0 <= tick <= MAX_TICK):
        raise ConfigError(f"{where}: tick: expected a whole number from 0 to {MAX_TICK}, got "
                          f"{show_value(tick)}")
    if not (vehicle is None or (isinstance(vehicle, str) and len(vehicle) <= MAX_NAME_CHARS)):
        raise ConfigError(f"{where}: vehicle: expected a vehicle id or null, got "
                          f"{show_value(vehicle)}")
    return Event(kind, tick, vehicle, e)


def rows_by_vehicle(table: pa.Table) -> dict[str, np.ndarray]:
    """Each vehicle's row numbers in ``table`` (in the table's order), by one
    sort of the ``vehicle`` column rather than one pass over it per vehicle."""
    enc = table["vehicle"].cast(pa.string()).combine_chunks().dictionary_encode()
    codes = enc.indices.to_numpy(zero_copy_only=False)
    order = np.argsort(codes, kind="stable")
    bounds = np.searchsorted(codes[order], np.arange(len(enc.dictionary) + 1))
    return {name: order[bounds[k]:bounds[k + 1]]
            for k, name in enumerate(enc.dictionary.to_pylist())}


# -- the files of states.parquet/ ----------------------------------------------------------
def state_files(states: Path) -> tuple[list[Path], list[Path]]:
    """The parts of a ``states.parquet`` folder, and the journals whose part
    is not in place (a journal whose part is in place: the crash came between
    writing the part and deleting its journal)."""
    parts = sorted(states.glob("part-*.parquet"))
    numbers = {x.name[len("part-"):-len(".parquet")] for x in parts}
    journals = [j for j in sorted(states.glob("_journal-*.arrows"))
                if j.name[len("_journal-"):-len(".arrows")] not in numbers]
    return parts, journals


def journal_batches(path: Path) -> tuple[list[pa.RecordBatch], bool]:
    """Every complete record batch of a journal, and whether it ended cleanly
    (False: the last one was cut short by a crash or a full disk, and is left
    out). The file is read whole: a regular file of at most
    ``MAX_STATE_FILE_BYTES``."""
    with open_bounded(path, MAX_STATE_FILE_BYTES, "a states journal", "a journal") as f:
        data = pa.py_buffer(read_bounded(f, MAX_STATE_FILE_BYTES))
    batches: list[pa.RecordBatch] = []
    try:
        reader = pa.ipc.open_stream(data)
        while True:
            batches.append(reader.read_next_batch())
    except StopIteration:
        return batches, True
    except (pa.ArrowException, ValueError, OSError):  # cut short
        pass
    try:  # nothing after the last complete batch?
        clean = data.size == _journal_end(data, len(batches))
    except (pa.ArrowException, ValueError, OSError, StopIteration):  # not even the schema
        clean = False
    return batches, clean


def _journal_end(data: pa.Buffer, n: int) -> int:
    """The byte offset after the schema and ``n`` record batches of a journal."""
    f = pa.BufferReader(data)
    reader = pa.ipc.MessageReader.open_stream(f)
    for _ in range(n + 1):
        reader.read_next_message()
    return int(f.tell())


def stored_schema(parts: Sequence[Path], journals: Sequence[Path] = ()) -> pa.Schema:
    """The schema a run's states were written with (its first part's, else its
    first readable journal's; the columns its classes added included)."""
    for x in parts:
        with open_bounded(x, MAX_STATE_FILE_BYTES, "states", "a states file") as f:
            try:
                return pq.read_schema(f).remove_metadata()
            except (pa.ArrowException, ValueError) as e:
                raise ConfigError(f"{x}: cannot read states: {e}") from None
    for j in journals:
        with open_bounded(j, MAX_STATE_FILE_BYTES, "a states journal", "a journal") as f:
            try:
                return pa.ipc.open_stream(read_bounded(f, MAX_STATE_FILE_BYTES)).schema
            except (pa.ArrowException, ValueError, OSError, StopIteration):
                continue
    return state_schema()


def read_states(folder: str | Path, columns: Sequence[str] | None = None) -> pa.Table:
    """A run's states as one table in tick order (``RunFolder.states``):
    ``folder`` is the run folder, its ``states.parquet`` folder (a folder of
    parts) or one Parquet file."""
    p = Path(folder)
    if p.is_dir() and (p / "states.parquet").exists():
        return RunFolder(p).states(columns)
    return RunFolder(p.parent).states(columns, p.name)

