"""``cosim recover RUN_DIR``: what a killed or failed run left, made readable.

A run killed hard (SIGKILL, a crash, a power cut) or stopped by a full disk
can leave ticks journalled but not in a Parquet part, hidden temporary
files, a truncated last line in ``events.jsonl``, and the summary written at
its start (``"complete": false``, stop reason ``running``) or none. This
module turns that into ordinary output:

- every journal whose part is missing becomes that part (written to a
  temporary file, renamed into place), then the journal is removed; a
  record batch cut short at the end of a journal is dropped and reported;
  a journal whose part is in place is removed;
- temporary files (``.part-*.tmp``, ``summary.json.tmp``) and disk reserves
  are removed; a truncated last line of ``events.jsonl`` is cut off;
- ``summary.json`` is rewritten when it is missing, unreadable or not
  complete: ``"complete": false, "recovered": true``, with what the folder
  tells (ticks, simulated time, state rows, vehicles, event counts, the stop
  reason of the stop event, else ``killed``).

It is idempotent: a second call finds nothing to do. It never runs a
simulation and never touches a complete run's files.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from cosim.errors import ConfigError
from cosim.logs.writers import journal_batches, read_states, stored_schema, write_json_atomic

log = logging.getLogger(__name__)

_TEMPORARY = ("summary.json.tmp", ".cosim-reserve", ".cosim-reserve-summary")


@dataclass
class Recovery:
    """What ``recover_run`` did (``actions``, one line each) and found."""

    folder: Path
    actions: list[str] = field(default_factory=list)
    rows: int = 0
    ticks: int | None = None

    @property
    def changed(self) -> bool:
        return bool(self.actions)


def _is_run(folder: Path) -> bool:
    return folder.is_dir() and any(
        (folder / n).exists() for n in ("events.jsonl", "states.parquet", "summary.json",
                                        "scenario.resolved.yaml"))


def _load_json(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _recover_states(states: Path, rec: Recovery) -> None:
    """Journals to parts; hidden temporary parts removed."""
    if not states.is_dir():
        return
    for tmp in sorted(states.glob(".part-*.tmp")):
        tmp.unlink()
        rec.actions.append(f"removed the unfinished part {tmp.name}")
    schema = stored_schema(sorted(states.glob("part-*.parquet")),
                           sorted(states.glob("_journal-*.arrows")))
    for journal in sorted(states.glob("_journal-*.arrows")):
        number = journal.name[len("_journal-"):-len(".arrows")]
        part = states / f"part-{number}.parquet"
        if part.exists():
            journal.unlink()
            rec.actions.append(f"removed {journal.name} (its part is in place)")
            continue
        batches, complete = journal_batches(journal)
        if batches:
            table = pa.Table.from_batches(batches, schema).unify_dictionaries().combine_chunks()
            tmp = states / f".{part.name}.tmp"
            try:
                pq.write_table(table, tmp, compression="zstd")
                os.replace(tmp, part)
            except OSError as e:
                tmp.unlink(missing_ok=True)
                raise OSError(e.errno, f"cannot write {part}: {e.strerror or e}") from e
            rec.actions.append(f"wrote {part.name} from {journal.name} ({table.num_rows} rows, "
                               f"{len(batches)} ticks)")
        if not complete:
            rec.actions.append(f"dropped a record cut short at the end of {journal.name} (a "
                               f"tick the run was writing when it stopped)")
        journal.unlink()
        if not batches:
            rec.actions.append(f"removed {journal.name} (no complete tick in it)")


def _recover_events(path: Path, rec: Recovery) -> dict[str, Any]:
    """Event counts and the last stop event; a truncated last line cut off."""
    counts: dict[str, int] = {}
    stop: dict[str, Any] | None = None
    last_tick = None
    if not path.exists():
        return {"counts": counts, "stop": stop, "tick": last_tick}
    data = path.read_bytes()
    good = data.rfind(b"\n") + 1
    if good < len(data):
        with open(path, "r+b") as f:
            f.truncate(good)
        rec.actions.append(f"cut a truncated last line off events.jsonl "
                           f"({len(data) - good} bytes)")
    for line in data[:good].splitlines():
        try:
            ev = json.loads(line)
        except ValueError:
            continue
        kind = str(ev.get("event"))
        counts[kind] = counts.get(kind, 0) + 1
        if isinstance(ev.get("tick"), int):
            last_tick = ev["tick"]
        if kind == "stop":
            stop = ev
    return {"counts": counts, "stop": stop, "tick": last_tick}


def recover_run(folder: str | Path) -> Recovery:
    """Make a run folder readable (see the module docstring); ``ConfigError``
    if ``folder`` is not a cosim run folder."""
    out = Path(folder)
    if not _is_run(out):
        raise ConfigError(f"{out}: not a cosim run folder (no summary.json, events.jsonl, "
                          f"states.parquet or scenario.resolved.yaml)")
    rec = Recovery(out)
    for name in _TEMPORARY:
        p = out / name
        if p.exists():
            p.unlink()
            rec.actions.append(f"removed {name}")
    fault = out / "faulthandler.log"
    if fault.exists() and fault.stat().st_size == 0:  # a run removes it when empty
        fault.unlink()
        rec.actions.append("removed the empty faulthandler.log")
    _recover_states(out / "states.parquet", rec)
    events = _recover_events(out / "events.jsonl", rec)
    summary = _load_json(out / "summary.json")
    states = out / "states.parquet"
    table = read_states(out) if states.exists() else None
    if table is not None and table.num_rows:
        ticks = table["tick"].to_numpy()
        rec.rows, rec.ticks = table.num_rows, int(ticks.max())
    if summary is not None and (summary.get("complete", True)
                                or (summary.get("recovered") and not rec.changed)):
        return rec  # finished (older runs have no "complete"), or recovered already
    new = dict(summary or {})
    stop = events["stop"]
    tick = rec.ticks if rec.ticks is not None else (events["tick"] or 0)
    if stop is not None:
        tick = max(tick, int(stop.get("tick", 0)))
    hz = new.get("physics_hz") or _physics_hz(out)
    new.update({
        "ticks": tick,
        "sim_time_s": tick / hz if hz else None,
        "state_rows": rec.rows,
        "events": events["counts"],
        "stop_reason": str(stop.get("reason")) if stop is not None else "killed",
        "complete": False,
        "recovered": True,
    })
    if rec.ticks is not None and table is not None:
        new.setdefault("vehicles", len(set(table["vehicle"].to_pylist())))
    new.setdefault("outputs", {"states": "states.parquet", "events": "events.jsonl",
                               "scenario": "scenario.resolved.yaml"})
    write_json_atomic(out / "summary.json", new)
    rec.actions.append(f"wrote summary.json (complete: false, recovered: true, stop reason "
                       f"{new['stop_reason']}, {tick} ticks)")
    return rec


def _physics_hz(out: Path) -> float | None:
    """The physics rate from scenario.resolved.yaml, if it is there."""
    import yaml

    try:
        doc = yaml.safe_load((out / "scenario.resolved.yaml").read_text())
        return float(doc["rates"]["physics_hz"])
    except (OSError, ValueError, TypeError, KeyError, yaml.YAMLError):
        return None
