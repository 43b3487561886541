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
simulation and never touches a complete run's files. The folder is
untrusted input (``runfolder``): it reads, truncates and replaces only
regular files inside it, bounded, and a damaged file is a ``ConfigError``
naming it (a line of ``events.jsonl`` that is not an event is skipped and
reported).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa

from cosim.errors import ConfigError
from cosim.logs.runfolder import (
    MAX_EVENTS_BYTES,
    RunFolder,
    journal_batches,
    physics_hz,
    state_files,
    stored_schema,
)
from cosim.logs.writers import replacing, write_json_atomic, write_part
from cosim.scenario.yaml_lines import open_bounded

log = logging.getLogger(__name__)

_TEMPORARY = ("summary.json.tmp", ".cosim-reserve", ".cosim-reserve-summary")
_MARKS = ("events.jsonl", "states.parquet", "summary.json", "scenario.resolved.yaml")


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


def _recover_states(run: RunFolder, rec: Recovery) -> None:
    """Journals to parts; hidden temporary parts removed."""
    if not run.has("states.parquet"):
        return
    states = run.file("states.parquet")
    if not states.is_dir():
        return
    for tmp in sorted(states.glob(".part-*.tmp")):
        tmp.unlink()  # a symlink is removed, never followed
        rec.actions.append(f"removed the unfinished part {tmp.name}")
    parts, journals = state_files(states)
    journals = [run.file(j.relative_to(run.path)) for j in journals]
    schema = stored_schema([run.file(x.relative_to(run.path)) for x in parts], journals)
    in_place = {x.name for x in parts}
    for journal in sorted(states.glob("_journal-*.arrows")):
        part = states / f"part-{journal.name[len('_journal-'):-len('.arrows')]}.parquet"
        if part.name in in_place:
            journal.unlink()
            rec.actions.append(f"removed {journal.name} (its part is in place)")
            continue
        batches, complete = journal_batches(run.file(journal.relative_to(run.path)))
        if batches:
            try:
                table = pa.Table.from_batches(batches, schema).unify_dictionaries()
            except (pa.ArrowException, ValueError) as e:
                raise ConfigError(f"{journal}: not the columns of the run's other states "
                                  f"files: {e}") from None
            with replacing(part, "wb", tmp=states / f".{part.name}.tmp") as f:
                write_part(table.combine_chunks(), f)
            rec.actions.append(f"wrote {part.name} from {journal.name} ({table.num_rows} rows, "
                               f"{len(batches)} ticks)")
        if not complete:
            rec.actions.append(f"dropped a record cut short at the end of {journal.name} (a "
                               f"tick the run was writing when it stopped)")
        journal.unlink()
        if not batches:
            rec.actions.append(f"removed {journal.name} (no complete tick in it)")


def _cut_partial_line(run: RunFolder, rec: Recovery) -> None:
    """A last line of ``events.jsonl`` without its newline (a run killed while
    writing it) cut off; the file is read backwards from its end, a block at
    a time, to the last newline."""
    p = run.file("events.jsonl")
    with open_bounded(p, MAX_EVENTS_BYTES, "events", "an events file") as f:
        size = f.seek(0, os.SEEK_END)
        end = size
        while end > 0:
            start = max(0, end - 65536)
            f.seek(start)
            block = f.read(end - start)
            nl = block.rfind(b"\n")
            if nl >= 0:
                end = start + nl + 1
                break
            end = start
    if end < size:
        os.truncate(p, end)
        rec.actions.append(f"cut a truncated last line off events.jsonl ({size - end} bytes)")


def _recover_events(run: RunFolder, rec: Recovery) -> dict[str, Any]:
    """Event counts and the last stop event; a truncated last line cut off."""
    counts: dict[str, int] = {}
    stop = None
    last_tick = None
    if not run.has("events.jsonl"):
        return {"counts": counts, "stop": stop, "tick": last_tick}
    _cut_partial_line(run, rec)
    skipped: list[str] = []
    for ev in run.events(skipped):
        counts[ev.kind] = counts.get(ev.kind, 0) + 1
        last_tick = ev.tick
        if ev.kind == "stop":
            stop = ev
    if skipped:
        log.warning("skipped %d line(s) of events.jsonl that are not events: %s",
                    len(skipped), "; ".join(skipped[:3]))
        rec.actions.append(f"left out {len(skipped)} line(s) of events.jsonl that are not "
                           f"events (the first: {skipped[0]})")
    return {"counts": counts, "stop": stop, "tick": last_tick}


def recover_run(folder: str | Path) -> Recovery:
    """Make a run folder readable (see the module docstring); ``ConfigError``
    if ``folder`` is not a cosim run folder, or a file in it is damaged
    beyond what a crash leaves."""
    out = Path(folder)
    run = RunFolder(out)
    if not any(run.has(n) for n in _MARKS):
        raise ConfigError(f"{out}: not a cosim run folder (no summary.json, events.jsonl, "
                          f"states.parquet or scenario.resolved.yaml)")
    rec = Recovery(out)
    for name in _TEMPORARY:
        if run.has(name):
            (out / name).unlink()  # a symlink is removed, never followed
            rec.actions.append(f"removed {name}")
    if run.has("faulthandler.log"):
        fault = run.file("faulthandler.log")
        if fault.is_file() and fault.stat().st_size == 0:  # a run removes it when empty
            fault.unlink()
            rec.actions.append("removed the empty faulthandler.log")
    _recover_states(run, rec)
    events = _recover_events(run, rec)
    summary = _summary(run, rec)
    table = run.states(["tick", "vehicle"]) if run.has("states.parquet") else None
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
        tick = max(tick, stop.tick)
    hz = _physics_hz(run, new)
    new.update({
        "ticks": tick,
        "sim_time_s": tick / hz if hz else None,
        "state_rows": rec.rows,
        "events": events["counts"],
        "stop_reason": str(stop.fields.get("reason"))[:200] if stop is not None else "killed",
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


def _summary(run: RunFolder, rec: Recovery) -> dict[str, Any] | None:
    """``summary.json``; None when it is missing or unreadable (cut short by
    a kill, damaged, not a file in the folder: it is then written again, in
    its place)."""
    p = run.path / "summary.json"
    if p.is_dir() and not p.is_symlink():
        raise ConfigError(f"{p}: a folder, where the run's summary belongs")
    try:
        return run.summary()
    except ConfigError as e:
        rec.actions.append(f"found summary.json unreadable ({e})")
        return None


def _physics_hz(run: RunFolder, summary: dict[str, Any]) -> float | None:
    """The physics rate: the summary's, else the resolved scenario's."""
    hz = physics_hz(summary)
    if hz is None:
        resolved = run.resolved()
        hz = resolved.physics_hz if resolved is not None else None
    return hz
