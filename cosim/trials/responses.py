"""Reading and checking a responses CSV, the trial server's export, for the analysis.

Owns the columns an export holds (``COLUMNS``, ``OPTIONAL_COLUMNS``), the
protocols, what each cell may hold and the bounds of the file. The CSV is
untrusted: it must be a regular file (a FIFO or a device is never opened for
reading), it is read up to ``MAX_BYTES`` and ``MAX_ROWS`` (larger files are
refused, not truncated), every row is checked and all problems are reported
at once as ``ConfigError`` lines ``file:line: column: message``. What it
returns, ``Responses``, holds only valid rows as numpy columns.

It computes no statistic and writes nothing; the display's ranges are the
trial server's own (``cosim.trials.measures``), never redefined here.
"""

from __future__ import annotations

import csv
import io
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim.errors import ConfigError
from cosim.scenario.yaml_lines import read_text_bounded
from cosim.trials.measures import SCREEN_MM_RANGE, SCREEN_PX_RANGE, VIEWING_DISTANCE_MM_RANGE

log = logging.getLogger(__name__)

#: the columns the trial server exports, in its order
COLUMNS: tuple[str, ...] = (
    "session", "participant", "trial_index", "practice", "protocol", "clip", "run",
    "condition_speed_kt", "condition_alt_agl_m", "condition_target", "frame",
    "video_time_s", "reaction_time_ms", "key", "target_in_view", "eccentricity_deg",
    "onscreen_distance_mm", "target_angular_size_deg", "viewing_distance_mm",
    "screen_width_mm", "screen_height_mm", "screen_width_px", "screen_height_px",
    "recognised",
)
#: columns read when present (exports of older versions lack them): the gap
#: seen from the camera and the camera's depth to the target (the altitude
#: analysis needs them) and the re-shown flag
OPTIONAL_COLUMNS: tuple[str, ...] = ("camera_gap_deg", "target_depth_m", "reshown")
PROTOCOLS = ("disappear", "recognise", "track")
#: the protocols whose responses are conspicuity angles (the target's eccentricity
#: from where the eyes are: the fixation mark, or the tracked dot)
CONSPICUITY = ("disappear", "track")
#: input limits: larger files are refused, not truncated
MAX_BYTES = 50 * 1024 * 1024
MAX_ROWS = 1_000_000
#: problems kept for the error message (the rest are counted)
MAX_PROBLEMS = 200


def _range(r: tuple[float, float]) -> tuple[float, bool, float]:
    return float(r[0]), True, float(r[1])


# numeric columns: name -> (required, lower bound, lower bound inclusive, upper bound);
# the upper bound is inclusive but for the angles whose tangent is a distance
# (90 deg is none). The ranges are what a trial can hold: the display's are the
# trial server's own (``cosim.trials.measures``), an altitude under 1 m is no
# flight, and every value is bounded so that no cell can overflow the analysis.
_NUMERIC: dict[str, tuple[bool, float, bool, float]] = {
    "trial_index": (True, 0.0, True, 1e7),
    "condition_speed_kt": (False, 0.0, True, 10_000.0),
    "condition_alt_agl_m": (False, 1.0, True, 100_000.0),
    "frame": (False, 0.0, True, 1e9),
    "video_time_s": (False, 0.0, True, 1e6),
    "reaction_time_ms": (False, 0.0, True, 600_000.0),
    "eccentricity_deg": (False, 0.0, True, 90.0),
    "onscreen_distance_mm": (False, 0.0, True, 100_000.0),
    "target_angular_size_deg": (False, 0.0, False, 180.0),
    "camera_gap_deg": (False, 0.0, True, 90.0),
    "target_depth_m": (False, 0.0, False, 1e6),
    "viewing_distance_mm": (True, *_range(VIEWING_DISTANCE_MM_RANGE)),
    "screen_width_mm": (True, *_range(SCREEN_MM_RANGE)),
    "screen_height_mm": (True, *_range(SCREEN_MM_RANGE)),
    "screen_width_px": (True, *_range(SCREEN_PX_RANGE)),
    "screen_height_px": (True, *_range(SCREEN_PX_RANGE)),
}
_OPEN_ABOVE = ("eccentricity_deg", "camera_gap_deg")
_INTEGER = {"trial_index", "frame", "screen_width_px", "screen_height_px"}
_FLAGS = ("practice", "target_in_view", "reshown")


@dataclass
class Responses:
    """Validated responses as numpy columns (one entry per row, file order).

    Numeric columns are float64 with NaN where the CSV cell was empty; text
    columns are lists of str. ``line`` holds each row's first line in the file.
    """

    path: str
    line: np.ndarray
    text: dict[str, list[str]]
    num: dict[str, np.ndarray]
    practice: np.ndarray  # bool
    target_in_view: np.ndarray  # bool
    recognised: np.ndarray  # float: NaN (empty), 0 or 1
    reshown: np.ndarray  # bool: the trial had been shown before (a reload)
    extra_columns: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.line.size)

    def subset(self, mask: np.ndarray) -> Responses:
        idx = np.flatnonzero(mask)
        return Responses(
            path=self.path, line=self.line[idx],
            text={k: [v[i] for i in idx] for k, v in self.text.items()},
            num={k: v[idx] for k, v in self.num.items()},
            practice=self.practice[idx], target_in_view=self.target_in_view[idx],
            recognised=self.recognised[idx], reshown=self.reshown[idx],
            extra_columns=self.extra_columns)


class _Problems:
    def __init__(self, path: str) -> None:
        self.path = path
        self.kept: list[str] = []
        self.more = 0

    def add(self, line: int, message: str) -> None:
        if len(self.kept) < MAX_PROBLEMS:
            self.kept.append(f"{self.path}:{line}: {message}")
        else:
            self.more += 1

    def raise_if_any(self) -> None:
        if self.kept:
            raise ConfigError(self.kept, self.more)


def read_responses(csv_path: str | Path, *, max_bytes: int = MAX_BYTES,
                   max_rows: int = MAX_ROWS) -> Responses:
    """Read and check a responses CSV; raise ``ConfigError`` listing every bad row.

    The header must hold every column of ``COLUMNS`` and may hold those of
    ``OPTIONAL_COLUMNS`` (in any order; other columns are ignored with a
    warning). Anything but a regular file (a FIFO, a device, a folder),
    files over ``max_bytes`` and files with more than ``max_rows`` data rows
    are refused. Each cell is checked:
    numbers finite and in range, flags 0/1, ``protocol`` one of
    ``PROTOCOLS``, ``recognised`` empty/0/1 (0/1 on "recognise" rows),
    ``eccentricity_deg`` and ``onscreen_distance_mm`` present on
    "disappear" rows with the target in view.
    """
    name = str(csv_path)
    # a regular file only (a FIFO would block for ever), at most max_bytes
    content = read_text_bounded(csv_path, max_bytes, "the responses CSV",
                                "a responses CSV").removeprefix("\ufeff")
    problems = _Problems(name)
    reader = csv.reader(io.StringIO(content, newline=""))
    try:
        header = next(reader, None)
    except csv.Error as e:
        raise ConfigError(f"{name}:1: unreadable header: {e}") from e
    if header is None or not any(h.strip() for h in header):
        raise ConfigError(f"{name}:1: empty file: expected a header with the columns "
                          f"{', '.join(COLUMNS)}")
    header = [h.strip() for h in header]
    missing = [c for c in COLUMNS if c not in header]
    dupes = sorted({h for h in header if header.count(h) > 1})
    if missing or dupes:
        msgs = []
        if missing:
            msgs.append(f"missing column{'s' if len(missing) > 1 else ''}: {', '.join(missing)}")
        if dupes:
            msgs.append(f"duplicate column{'s' if len(dupes) > 1 else ''}: {', '.join(dupes)}")
        raise ConfigError(f"{name}:1: {'; '.join(msgs)}")
    extra = [h for h in header if h not in COLUMNS + OPTIONAL_COLUMNS]
    if extra:
        log.warning("%s: ignoring unknown columns: %s", name, ", ".join(extra))
    col = {c: header.index(c) for c in COLUMNS + OPTIONAL_COLUMNS if c in header}
    absent = {c: "" for c in OPTIONAL_COLUMNS if c not in header}

    text: dict[str, list[str]] = {c: [] for c in ("session", "participant", "protocol", "clip",
                                                  "run", "condition_target", "key")}
    num: dict[str, list[float]] = {c: [] for c in _NUMERIC}
    flags: dict[str, list[bool]] = {c: [] for c in _FLAGS}
    recognised: list[float] = []
    lines: list[int] = []
    rows = 0
    prev_line = 1
    while True:
        start = prev_line + 1
        try:
            row = next(reader, None)
        except csv.Error as e:
            raise ConfigError(problems.kept + [f"{name}:{start}: unreadable CSV: {e}"],
                              problems.more) from e
        prev_line = reader.line_num
        if row is None:
            break
        if not row or (len(row) == 1 and not row[0].strip()):
            continue  # blank line
        rows += 1
        if rows > max_rows:
            raise ConfigError(f"{name}:{start}: more than {max_rows} data rows; refused "
                              "(split the file or analyse fewer sessions)")
        if len(row) != len(header):
            problems.add(start, f"expected {len(header)} fields, got {len(row)}")
            continue
        cells = {c: row[i].strip() for c, i in col.items()} | absent
        ok = True
        values: dict[str, float] = {}
        for c, (required, lo, lo_incl, hi) in _NUMERIC.items():
            v = _number(cells[c], c, required, lo, lo_incl, hi, c in _INTEGER)
            if isinstance(v, str):
                problems.add(start, f"{c}: {v}")
                ok = False
            else:
                values[c] = v
        fl: dict[str, bool] = {}
        for c in _FLAGS:
            if c in ("target_in_view", "reshown") and cells[c] == "":  # no press, or unknown
                fl[c] = False
                continue
            if cells[c] not in ("0", "1"):
                problems.add(start, f"{c}: expected 0 or 1, got {cells[c]!r}")
                ok = False
            else:
                fl[c] = cells[c] == "1"
        protocol = cells["protocol"]
        if protocol not in PROTOCOLS:
            problems.add(start, f"protocol: expected one of {', '.join(map(repr, PROTOCOLS))}, "
                                f"got {protocol!r}")
            ok = False
        rec = cells["recognised"]
        if rec not in ("", "0", "1"):
            problems.add(start, f"recognised: expected empty, 0 or 1, got {rec!r}")
            ok = False
        elif protocol == "recognise" and rec == "":
            problems.add(start, "recognised: required (0 or 1) on a 'recognise' response")
            ok = False
        if not cells["condition_target"]:
            problems.add(start, "condition_target: required, got an empty cell")
            ok = False
        if ok and protocol in CONSPICUITY and fl["target_in_view"]:
            for c in ("eccentricity_deg", "onscreen_distance_mm"):
                if math.isnan(values[c]):
                    problems.add(start, f"{c}: required on a {protocol!r} response with "
                                        "the target in view, got an empty cell")
                    ok = False
        if not ok:
            continue
        lines.append(start)
        for c in text:
            text[c].append(cells[c])
        for c in _NUMERIC:
            num[c].append(values[c])
        for c in _FLAGS:
            flags[c].append(fl[c])
        recognised.append(math.nan if rec == "" else float(rec))
    problems.raise_if_any()
    return Responses(
        path=name, line=np.asarray(lines, dtype=np.int64), text=text,
        num={c: np.asarray(v, dtype=float) for c, v in num.items()},
        practice=np.asarray(flags["practice"], dtype=bool),
        target_in_view=np.asarray(flags["target_in_view"], dtype=bool),
        recognised=np.asarray(recognised, dtype=float),
        reshown=np.asarray(flags["reshown"], dtype=bool), extra_columns=extra)


def _number(cell: str, column: str, required: bool, lo: float, lo_incl: bool, hi: float,
            integer: bool) -> float | str:
    """The cell as a float (NaN when empty and optional) or a problem message."""
    if cell == "":
        return "required, got an empty cell" if required else math.nan
    try:
        v = float(cell)
    except ValueError:
        return f"expected a number, got {cell[:40]!r}"
    if not math.isfinite(v):
        return f"expected a finite number, got {cell[:40]!r}"
    if integer and v != int(v):
        return f"expected a whole number, got {cell!r}"
    hi_incl = column not in _OPEN_ABOVE
    if v < lo or (v == lo and not lo_incl) or v > hi or (v == hi and not hi_incl):
        left = "[" if lo_incl else "("
        right = "]" if hi_incl else ")"
        return f"expected a value in {left}{lo:g}, {hi:g}{right}, got {cell!r}"
    return v

