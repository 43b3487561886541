"""Replaying a run folder: the scenario it recorded run again, unpaced, with
the operator's commands it logged applied at their ticks, and the outputs
compared with the original's.

A run folder holds what a replay needs: ``scenario.resolved.yaml`` (the
scenario as run, every vehicle listed), ``summary.json`` (the tick it
stopped at: the replay stops there too) and ``commands.jsonl`` (the command
inbox's log, ``cosim.sync.inbox``; none: no operator commands). Compared:

- ``states.parquet``: the states table, every row and column bit for bit
  (the table, not the file's bytes: its parts are cut by the wall clock);
- every video the cameras wrote (``summary.json``'s ``cameras`` section,
  the operator view's too): equal bytes, else every decoded frame equal
  (a sha256 of each); each camera's ground-truth CSV byte for byte.

``commands.jsonl`` is untrusted input: at most ``MAX_COMMAND_LINES`` lines of
at most ``MAX_COMMAND_LINE_BYTES`` each; a line that is not a logged command
is a ``ConfigError`` naming the file and line and what was expected. Reads
the original folder only; writes only into the replay's own folder.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from cosim.core.limits import MAX_NAME_CHARS
from cosim.errors import ConfigError
from cosim.logs.resolved import MAX_RESOLVED_BYTES, RESOLVED
from cosim.logs.runfolder import MAX_TICK, RunFolder, parse_json
from cosim.scenario import Scenario, parse_scenario
from cosim.scenario.yaml_lines import open_bounded
from cosim.sync.inbox import COMMANDS_LOG, MAX_COMMANDS, CommandInbox, parse_spec
from cosim.sync.runner import Run, RunResult

log = logging.getLogger(__name__)

#: ``commands.jsonl``: lines (as many as an inbox takes), and bytes a line (a
#: command's JSON is at most ``inbox.MAX_SPEC_BYTES``)
MAX_COMMAND_LINES = MAX_COMMANDS
MAX_COMMAND_LINE_BYTES = 8 * 1024
#: a video compared frame by frame, at most this big and this many frames
MAX_VIDEO_BYTES = 64 * 1024 ** 3
MAX_VIDEO_FRAMES = 10_000_000
#: a ground-truth CSV compared byte for byte, read this much at a time
_CHUNK = 1024 * 1024
_ENTRY_KEYS = ("seq", "tick", "time_s", "vehicle", "command", "source")


@dataclass
class ReplayResult:
    """``identical``: every compared output equal; ``differences`` says where
    they are not, ``compared`` what was compared and how; ``run`` is the
    replay's own ``RunResult``."""

    identical: bool
    differences: list[str]
    run: RunResult
    compared: list[str] = field(default_factory=list)


def read_commands(path: Path, ids: list[str] | None = None, control_every: int | None = None,
                  stop_tick: int | None = None) -> list[dict[str, Any]]:
    """The logged commands of ``commands.jsonl`` at ``path``, checked: each line
    one command ``{"seq", "tick", "time_s", "vehicle", "command", "source"}``,
    numbered 0, 1, ... in tick order; with ``ids`` / ``control_every`` /
    ``stop_tick``, of a vehicle of the run at one of its exchanges before it
    stopped. ``ConfigError`` naming ``path:line`` and what was expected."""
    out: list[dict[str, Any]] = []
    for n, line in _lines(path):
        where = f"{path}:{n}"
        e = parse_json(line, str(path), n)
        if not isinstance(e, dict):
            raise ConfigError(f"{where}: expected a logged command (a JSON object with "
                              f"{', '.join(_ENTRY_KEYS)}), got {type(e).__name__}")
        keys = set(e)
        if keys != set(_ENTRY_KEYS):
            missing, extra = sorted(set(_ENTRY_KEYS) - keys), sorted(keys - set(_ENTRY_KEYS))
            raise ConfigError(f"{where}: expected the keys {', '.join(_ENTRY_KEYS)}"
                              + (f"; missing {', '.join(missing)}" if missing else "")
                              + (f"; unknown {', '.join(map(repr, extra))}" if extra else ""))
        seq, tick, time_s = e["seq"], e["tick"], e["time_s"]
        if seq != len(out) or isinstance(seq, bool):
            raise ConfigError(f"{where}: seq is {seq!r}; expected {len(out)} (commands are "
                              f"numbered 0, 1, ... in the order they were applied)")
        if not isinstance(tick, int) or isinstance(tick, bool) or not 0 <= tick <= MAX_TICK:
            raise ConfigError(f"{where}: tick is {tick!r}; expected a whole number 0 to "
                              f"{MAX_TICK}")
        if out and tick < out[-1]["tick"]:
            raise ConfigError(f"{where}: tick {tick} is before the previous command's "
                              f"({out[-1]['tick']}); commands are logged in tick order")
        if control_every is not None and tick % control_every:
            raise ConfigError(f"{where}: tick {tick} is not an exchange of the run (every "
                              f"{control_every} ticks)")
        if stop_tick is not None and tick >= stop_tick:
            raise ConfigError(f"{where}: tick {tick} is at or after the tick the run stopped "
                              f"at ({stop_tick}): the run never reached it")
        if not isinstance(time_s, (int, float)) or isinstance(time_s, bool) \
                or not math.isfinite(time_s):
            raise ConfigError(f"{where}: time_s is {time_s!r}; expected a number")
        vehicle, source = e["vehicle"], e["source"]
        if not isinstance(vehicle, str) or (ids is not None and vehicle not in ids):
            raise ConfigError(f"{where}: vehicle {vehicle!r} is not a vehicle of the run"
                              + (f" ({', '.join(ids[:5])}{', ...' if len(ids) > 5 else ''})"
                                 if ids is not None else ""))
        if not isinstance(source, str) or not 0 < len(source) <= MAX_NAME_CHARS:
            raise ConfigError(f"{where}: source is {source!r}; expected a name of 1 to "
                              f"{MAX_NAME_CHARS} characters")
        parse_spec(e["command"], where)  # a command of the vocabulary, or why not
        out.append(e)
    return out


def _lines(path: Path) -> Iterator[tuple[int, bytes]]:
    """(number, bytes) of each line, bounded (module docstring)."""
    limit = MAX_COMMAND_LINES * MAX_COMMAND_LINE_BYTES
    with open_bounded(path, limit, "commands", "a commands log") as f:
        for n, line in enumerate(iter(lambda: f.readline(MAX_COMMAND_LINE_BYTES + 1), b""), 1):
            if n > MAX_COMMAND_LINES:
                raise ConfigError(f"{path}:{n}: more than {MAX_COMMAND_LINES} commands; a "
                                  f"replay reads at most {MAX_COMMAND_LINES}")
            if len(line) > MAX_COMMAND_LINE_BYTES:
                raise ConfigError(f"{path}:{n}: a line of more than {MAX_COMMAND_LINE_BYTES} "
                                  f"bytes; a logged command takes fewer")
            if not line.endswith(b"\n"):
                raise ConfigError(f"{path}:{n}: the last line is cut short (the run was "
                                  f"killed while writing it); expected a whole line")
            yield n, line


def replay_run(run_dir: Path, out_dir: Path, *, backend: str = "inline",
               workers: int | None = None,
               progress: bool | Callable[[int, int], None] = False) -> ReplayResult:
    """Run ``run_dir``'s scenario again into ``out_dir`` (unpaced, stopped at
    the tick the original stopped at, its logged commands at their ticks) and
    compare the outputs (module docstring). ``progress``: a callback
    ``(tick, total)``, or True for a log line every 10 s. ``ConfigError``: a
    run folder that cannot be replayed, saying why."""
    rf = RunFolder(run_dir)
    if Path(out_dir).resolve() == rf.root:
        raise ConfigError(f"{out_dir}: the replay would overwrite the run it replays; give "
                          f"another folder")
    scn, stop_tick = _scenario(rf)
    ids = [v.id for v in scn.vehicles]
    entries = (read_commands(rf.file(COMMANDS_LOG), ids, scn.rates.control_every, stop_tick)
               if rf.has(COMMANDS_LOG) else [])
    log.info("replaying %s: %d vehicles, %d ticks, %d logged command(s)", rf.path, len(ids),
             stop_tick, len(entries))
    sources = {e["source"] for e in entries}
    if len(sources) > 1:
        raise ConfigError(f"{rf.path / COMMANDS_LOG}: commands from several sources "
                          f"({', '.join(sorted(sources))}); one inbox logs one source")
    inbox = CommandInbox(source=sources.pop() if sources else "operator", replay=entries)
    mavlink = None
    if scn.mavlink is not None:  # the same links, without the original's socket
        from cosim.mavlink import MavlinkConfig

        config = MavlinkConfig.of_scenario(scn.mavlink, ids)
        mavlink = dataclasses.replace(config, url=None) if config is not None else None
    run = Run(scn, out_dir, backend=backend, workers=workers, mavlink=mavlink,
              extra_participants=[inbox],
              progress=progress if callable(progress) else (_Every10s() if progress else None))
    res = run.run()
    if res.error is not None and res.ticks < stop_tick:
        return ReplayResult(False, [f"the replay stopped at tick {res.ticks} "
                                    f"({res.stop_reason}: {res.error})"], res)
    differences: list[str] = []
    compared: list[str] = []
    if res.ticks != stop_tick:
        differences.append(f"the original stopped at tick {stop_tick}, the replay at "
                           f"{res.ticks}")
    _compare_states(rf, RunFolder(out_dir), differences, compared)
    _compare_cameras(rf, Path(out_dir), differences, compared)
    return ReplayResult(not differences, differences, res, compared)


class _Every10s:
    """Progress as a log line every 10 s of wall time."""

    def __init__(self) -> None:
        import time

        self.clock = time.monotonic
        self.last = self.clock()

    def __call__(self, tick: int, total: int) -> None:
        now = self.clock()
        if now - self.last >= 10.0 or tick >= total:
            self.last = now
            log.info("replay: tick %d of %d", tick, total)


def _scenario(rf: RunFolder) -> tuple[Scenario, int]:
    """The scenario as run, to stop at the tick the original stopped at."""
    for name in (RESOLVED, "summary.json"):
        if not rf.has(name):
            raise ConfigError(f"{rf.path}: no {name}; a replay needs the run's {RESOLVED} and "
                              f"summary.json")
    path = rf.file(RESOLVED)
    scn = parse_scenario(rf.text(RESOLVED, MAX_RESOLVED_BYTES, "resolved scenario"), str(path))
    summary = rf.summary()
    assert summary is not None
    where = rf.path / "summary.json"
    ticks = summary.get("ticks")
    if not isinstance(ticks, int) or isinstance(ticks, bool) or not 0 <= ticks <= MAX_TICK:
        raise ConfigError(f"{where}: ticks is {ticks!r}; expected a whole number 0 to "
                          f"{MAX_TICK}")
    hz = summary.get("physics_hz")
    if hz != scn.rates.physics_hz:
        raise ConfigError(f"{where}: physics_hz {hz!r} is not the scenario's "
                          f"({scn.rates.physics_hz:g}): not the summary of that run")
    if summary.get("stop_reason") == "running":
        log.warning("%s: the run has not finished (or was killed): replaying its %d ticks",
                    rf.path, ticks)
    if ticks == 0:
        raise ConfigError(f"{where}: the run stopped at tick 0, before its first exchange: "
                          f"nothing to replay")
    shortened = scn.with_duration(ticks / scn.rates.physics_hz)
    if shortened.total_ticks != ticks:
        raise ConfigError(f"{where}: the run stopped at tick {ticks}, which is not an "
                          f"exchange of its scenario (every {scn.rates.control_every} ticks)")
    return shortened, ticks


def _compare_states(a: RunFolder, b: RunFolder, differences: list[str],
                    compared: list[str]) -> None:
    ta, tb = _plain(a.states()), _plain(b.states())
    compared.append(f"states.parquet: {ta.num_rows} rows, {ta.num_columns} columns")
    if ta.equals(tb):
        return
    if ta.column_names != tb.column_names:
        differences.append(f"states.parquet: columns {ta.column_names} in the original, "
                           f"{tb.column_names} in the replay")
        return
    retyped = [f"{f.name} is {f.type} in the original, {g.type} in the replay"
               for f, g in zip(ta.schema, tb.schema) if f.type != g.type]
    if retyped:
        differences.append(f"states.parquet: {'; '.join(retyped)}")
        return
    if ta.num_rows != tb.num_rows:
        differences.append(f"states.parquet: {ta.num_rows} rows in the original, "
                           f"{tb.num_rows} in the replay")
        return
    for name in ta.column_names:
        ca, cb = ta[name].to_numpy(zero_copy_only=False), tb[name].to_numpy(zero_copy_only=False)
        if ca.dtype.kind == "f":
            same = (ca == cb) | (np.isnan(ca) & np.isnan(cb))
            same &= np.signbit(ca) == np.signbit(cb)
        else:
            same = ca == cb
        if not same.all():
            i = int(np.flatnonzero(~same)[0])
            at = (f"tick {ta['tick'][i].as_py()}, vehicle {ta['vehicle'][i].as_py()}"
                  if {"tick", "vehicle"} <= set(ta.column_names) else f"row {i + 1}")
            differences.append(f"states.parquet: {name} differs in {int((~same).sum())} rows, "
                               f"first at {at}: {ca[i]!r} in the original, {cb[i]!r} in the "
                               f"replay")


def _plain(t: pa.Table) -> pa.Table:
    """The table's values, whatever its chunks and dictionaries."""
    cols = [c.cast(c.type.value_type) if pa.types.is_dictionary(c.type) else c
            for c in t.columns]
    return pa.table(cols, names=t.column_names).combine_chunks()


def _camera_files(rf: RunFolder) -> list[tuple[str, str]]:
    """(kind, path in the folder) of every video and ground-truth file the
    original's summary lists."""
    summary = rf.summary() or {}
    cams = summary.get("cameras")
    if cams is None:
        return []
    where = rf.path / "summary.json"
    if not isinstance(cams, dict):
        raise ConfigError(f"{where}: cameras: expected an object, got {type(cams).__name__}")
    streams = cams.get("streams", [])
    if not isinstance(streams, list):
        raise ConfigError(f"{where}: cameras.streams: expected a list")
    out: list[tuple[str, str]] = []
    for i, s in enumerate(streams):
        if not isinstance(s, dict):
            raise ConfigError(f"{where}: cameras.streams[{i}]: expected an object")
        out += [(kind, _rel(s.get(key), f"{where}: cameras.streams[{i}].{key}"))
                for kind, key in (("video", "video"), ("csv", "ground_truth"))]
    op = cams.get("operator")
    if isinstance(op, dict) and "video" in op:
        out.append(("video", _rel(op["video"], f"{where}: cameras.operator.video")))
    return out


def _rel(v: Any, where: str) -> str:
    if not isinstance(v, str) or not v or Path(v).is_absolute() or ".." in Path(v).parts:
        raise ConfigError(f"{where}: expected a file's path inside the run folder, got {v!r}")
    return v


def _compare_cameras(rf: RunFolder, out: Path, differences: list[str],
                     compared: list[str]) -> None:
    for kind, rel in _camera_files(rf):
        a, b = rf.file(rel), out / rel
        if not b.is_file():
            differences.append(f"{rel}: not written by the replay")
            continue
        if _same_bytes(a, b):
            compared.append(f"{rel}: the same bytes")
        elif kind == "csv":
            differences.append(f"{rel}: the ground truth differs")
        else:
            diff = _video_difference(a, b)
            if diff is None:
                compared.append(f"{rel}: the same frames (the files' bytes differ)")
            else:
                differences.append(f"{rel}: {diff}")


def _same_bytes(a: Path, b: Path) -> bool:
    with open_bounded(a, MAX_VIDEO_BYTES, "camera output", "a camera output") as fa, \
            open(b, "rb") as fb:
        while True:
            x, y = fa.read(_CHUNK), fb.read(_CHUNK)
            if x != y:
                return False
            if not x:
                return True


def _video_difference(a: Path, b: Path) -> str | None:
    """Where the decoded frames of two videos first differ (None: nowhere)."""
    fa, fb = _frame_digests(a), _frame_digests(b)
    n = 0
    while True:
        x, y = next(fa, None), next(fb, None)
        if x is None and y is None:
            return None
        if x is None or y is None:
            return (f"{n} frames in the {'original' if x is None else 'replay'}, more in "
                    f"the other")
        if x != y:
            return f"frame {n} differs (decoded)"
        n += 1


def _frame_digests(path: Path) -> Iterator[bytes]:
    """A sha256 of each decoded frame of the video at ``path`` (at most
    ``MAX_VIDEO_FRAMES``)."""
    import cv2

    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise ConfigError(f"{path}: cannot be decoded as a video")
    try:
        for n in range(MAX_VIDEO_FRAMES + 1):
            ok, img = cap.read()
            if not ok:
                return
            if n == MAX_VIDEO_FRAMES:
                raise ConfigError(f"{path}: more than {MAX_VIDEO_FRAMES} frames")
            yield hashlib.sha256(img.tobytes()).digest()
    finally:
        cap.release()
