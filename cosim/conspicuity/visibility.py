"""How long each target is visible: passes from the per-frame ground truth.

A **pass** is a maximal run of consecutive frames (frame numbers without a
gap) in which the target is ``in_view`` (any part of it in the image).

Convention for the duration: ``visible_s = frames_in_view * frame_period_s``.
Each frame stands for one frame period of video, so this is exactly how long
the target is on screen when the clip is played back, and for a pass that
lasts ``T`` seconds of simulated time it is within one frame period of ``T``
(n samples at period p fall in an interval of length T when
``(n - 1) p <= T < (n + 1) p``). For a straight level pass of a nadir camera
at height ``h`` and ground speed ``v`` over a target ``L`` long along the
track, ``T = (2 h tan(vfov / 2) + L) / v``.
``first_visible_s`` / ``last_visible_s`` are the times of the first and last
in-view frames, so ``last - first = visible_s - period``.

The frame in a pass where the target is closest to the image centre (least
``eccentricity_deg``) is the **overhead** frame: for a nadir camera, the
moment the vehicle is above the target (experiment 1's trial start).

A pass's ``screen_direction`` is where the target travels across the image:
``up``, ``down``, ``left`` or ``right``, the larger of the horizontal and
vertical moves of its centre from the first to the last frame of the pass
where the centre is known (empty if it is known in fewer than two).
Experiment 1 needs all four.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.core.limits import MAX_NUMBER
from cosim.errors import ConfigError
from cosim.logs import RunFolder, replacing
from cosim.logs.resolved import is_number
from cosim.logs.runfolder import MAX_GROUND_TRUTH_BYTES, MAX_TIME_S, physics_hz
from cosim.scenario.yaml_lines import open_bounded

#: ground-truth columns this module needs
REQUIRED_COLUMNS = ("frame", "time_s", "vehicle", "camera", "target", "in_view")
#: a camera's frame rate, as a run's summary may give it (Hz)
MAX_RATE_HZ = 10_000.0


class GroundTruthError(ConfigError):
    """A ground-truth file (or the summary naming it) is missing, unreadable
    or malformed: bad input, exit 2."""


@dataclass(frozen=True)
class GtRow:
    frame: int
    time_s: float
    in_view: bool
    eccentricity_deg: float = math.nan
    angular_size_deg: float = math.nan
    range_m: float = math.nan
    center_x_px: float = math.nan
    center_y_px: float = math.nan


@dataclass(frozen=True)
class Pass:
    index: int  # 1-based, in time order
    first_frame: int
    last_frame: int
    first_visible_s: float
    last_visible_s: float
    frames: int
    visible_s: float
    overhead_frame: int
    overhead_s: float
    min_eccentricity_deg: float
    max_angular_size_deg: float
    min_range_m: float
    screen_direction: str = ""


@dataclass(frozen=True)
class TargetVisibility:
    vehicle: str
    camera: str
    target: str
    frame_period_s: float
    frames: int  # frames in the ground truth for this target
    passes: tuple[Pass, ...] = field(default=())

    @property
    def visible_s(self) -> float:
        """Total over every pass."""
        return sum(p.visible_s for p in self.passes)

    @property
    def first_visible_s(self) -> float | None:
        return self.passes[0].first_visible_s if self.passes else None

    @property
    def last_visible_s(self) -> float | None:
        return self.passes[-1].last_visible_s if self.passes else None


def _num(text: str | None, name: str) -> float:
    """A number of the file (empty: NaN, not known); at most ``MAX_NUMBER``."""
    if text is None or text == "":
        return math.nan
    try:
        x = float(text)
    except ValueError:
        raise ValueError(f"{name}: expected a number, got {text[:40]!r}") from None
    if not (math.isnan(x) or abs(x) <= MAX_NUMBER):
        raise ValueError(f"{name}: expected a number within +-{MAX_NUMBER:.10g}, got {text[:40]!r}")
    return x


def _whole(text: str, name: str, hi: float) -> int:
    try:
        x = int(text)
    except ValueError:
        x = -1
    if not 0 <= x <= hi:
        raise ValueError(f"{name}: expected a whole number from 0 to {hi:.10g}, got {text[:40]!r}")
    return x


def _row(r: dict[str, str]) -> GtRow:
    time_s = _num(r["time_s"], "time_s")
    if not 0 <= time_s <= MAX_TIME_S:  # (NaN fails too)
        raise ValueError(f"time_s: expected 0 to {MAX_TIME_S:.10g} s, got {r['time_s'][:40]!r}")
    return GtRow(frame=_whole(r["frame"], "frame", MAX_NUMBER), time_s=time_s,
                 in_view=_whole(r["in_view"], "in_view", 1) == 1,
                 eccentricity_deg=_num(r.get("eccentricity_deg"), "eccentricity_deg"),
                 angular_size_deg=_num(r.get("angular_size_deg"), "angular_size_deg"),
                 range_m=_num(r.get("range_m"), "range_m"),
                 center_x_px=_num(r.get("center_x_px"), "center_x_px"),
                 center_y_px=_num(r.get("center_y_px"), "center_y_px"))


def read_ground_truth(path: str | Path) -> dict[tuple[str, str, str], list[GtRow]]:
    """Rows of one ground-truth CSV grouped by (vehicle, camera, target), in
    frame order. The file is untrusted: a regular file of at most
    ``MAX_GROUND_TRUTH_BYTES``, every value checked (``GroundTruthError``
    with its line otherwise)."""
    p = Path(path)
    out: dict[tuple[str, str, str], list[GtRow]] = {}
    n = 1
    try:
        with open_bounded(p, MAX_GROUND_TRUTH_BYTES, "ground truth", "a ground-truth file") as b:
            reader = csv.DictReader(io.TextIOWrapper(b, encoding="utf-8", newline=""))
            missing = [c for c in REQUIRED_COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                raise GroundTruthError(f"{p}: not a ground-truth file: missing column(s) "
                                       f"{', '.join(missing)}")
            for r in reader:
                n = reader.line_num
                if None in r or None in r.values():
                    raise GroundTruthError(f"{p}:{n}: expected {len(reader.fieldnames or [])} "
                                           f"fields, as in the header")
                out.setdefault((r["vehicle"], r["camera"], r["target"]), []).append(_row(r))
    except GroundTruthError:
        raise
    except ConfigError as e:
        raise GroundTruthError(e.problems) from None
    except UnicodeDecodeError as e:
        raise GroundTruthError(f"{p}: not UTF-8 text (byte {e.object[e.start]:#04x})") from None
    except (ValueError, csv.Error) as e:
        raise GroundTruthError(f"{p}:{n}: {e}") from None
    for rows in out.values():
        rows.sort(key=lambda x: x.frame)
    return out


def _nanmin(xs: Iterable[float]) -> float:
    vals = [x for x in xs if not math.isnan(x)]
    return min(vals) if vals else math.nan


def passes(rows: Sequence[GtRow], frame_period_s: float) -> list[Pass]:
    """The passes in one target's rows (sorted by frame)."""
    runs: list[list[GtRow]] = []
    for r in rows:
        if not r.in_view:
            continue
        if runs and runs[-1][-1].frame == r.frame - 1:
            runs[-1].append(r)
        else:
            runs.append([r])
    out = []
    for i, run in enumerate(runs, start=1):
        ecc = [(x.eccentricity_deg, x.frame) for x in run if not math.isnan(x.eccentricity_deg)]
        over = min(ecc)[1] if ecc else run[len(run) // 2].frame
        over_row = next(x for x in run if x.frame == over)
        sizes = [x.angular_size_deg for x in run if not math.isnan(x.angular_size_deg)]
        out.append(Pass(index=i, first_frame=run[0].frame, last_frame=run[-1].frame,
                        first_visible_s=run[0].time_s, last_visible_s=run[-1].time_s,
                        frames=len(run), visible_s=len(run) * frame_period_s,
                        overhead_frame=over, overhead_s=over_row.time_s,
                        min_eccentricity_deg=_nanmin(x.eccentricity_deg for x in run),
                        max_angular_size_deg=max(sizes) if sizes else math.nan,
                        min_range_m=_nanmin(x.range_m for x in run),
                        screen_direction=screen_direction(run)))
    return out


def screen_direction(run: Sequence[GtRow]) -> str:
    """Where the target travels across the image in a pass (module docstring)."""
    known = [x for x in run if not (math.isnan(x.center_x_px) or math.isnan(x.center_y_px))]
    if len(known) < 2:
        return ""
    dx = known[-1].center_x_px - known[0].center_x_px
    dy = known[-1].center_y_px - known[0].center_y_px  # image y grows downwards
    if dx == dy == 0:
        return ""
    if abs(dx) >= abs(dy):
        return "right" if dx > 0 else "left"
    return "down" if dy > 0 else "up"


def _period_from_times(rows: Sequence[GtRow], where: str = "") -> float:
    """The frame period from the rows' times: the first-to-last span over the
    frame count between them (precise even with times rounded in the file)."""
    if len(rows) < 2 or rows[-1].frame == rows[0].frame:
        raise GroundTruthError(f"{where}cannot tell the frame period from fewer than two "
                               f"frames; give the camera's rate_hz")
    period = (rows[-1].time_s - rows[0].time_s) / (rows[-1].frame - rows[0].frame)
    if not period > 0:
        raise GroundTruthError(f"{where}time_s does not grow with the frame number (frame "
                               f"{rows[0].frame} at {rows[0].time_s:g} s, frame "
                               f"{rows[-1].frame} at {rows[-1].time_s:g} s)")
    return period


def visibility(path: str | Path, rate_hz: float | None = None) -> list[TargetVisibility]:
    """Per target visibility from one ground-truth CSV; ``rate_hz`` is the
    camera's frame rate (default: read from the frame times)."""
    out = []
    for (vehicle, camera, target), rows in read_ground_truth(path).items():
        period = 1.0 / rate_hz if rate_hz else _period_from_times(rows, f"{path}: ")
        out.append(TargetVisibility(vehicle=vehicle, camera=camera, target=target,
                                    frame_period_s=period, frames=len(rows),
                                    passes=tuple(passes(rows, period))))
    return out


def camera_entries(run_dir: str | Path) -> list[dict[str, Any]]:
    """The run's cameras: summary.json's ``cameras`` list, or its ``streams``
    list when ``cameras`` is a mapping (paths made absolute),
    or, without one, every ``cameras/*.gt.csv`` in the folder. The folder is
    untrusted (``cosim.logs.runfolder``): an entry's files must be inside it."""
    run = RunFolder(run_dir)
    summary = run.summary() or {}
    where = run.path / "summary.json"
    cams = summary.get("cameras") or []
    if isinstance(cams, dict):  # {"streams": [...], "codec": ...}
        cams = cams.get("streams") or []
    if not isinstance(cams, list):
        raise GroundTruthError(f"{where}: cameras: expected a list of streams, got "
                               f"{type(cams).__name__}")
    entries: list[dict[str, Any]] = []
    for i, c in enumerate(cams):
        if not isinstance(c, dict):
            raise GroundTruthError(f"{where}: cameras[{i}]: expected an object, got "
                                   f"{type(c).__name__}")
        entry = dict(c)
        rate = entry.get("rate_hz")
        if rate is not None and not (is_number(rate) and 0 < rate <= MAX_RATE_HZ):
            raise GroundTruthError(f"{where}: cameras[{i}].rate_hz: expected a frame rate "
                                   f"above 0 and at most {MAX_RATE_HZ:g} Hz, got {rate!r}")
        for key in ("video", "ground_truth"):
            value = entry.get(key)
            if value is None or value == "":
                continue
            if not isinstance(value, str) or Path(value).is_absolute():
                raise GroundTruthError(f"{where}: cameras[{i}].{key}: expected a path inside "
                                       f"the run folder, got {str(value)[:80]!r}")
            entry[key] = str(run.file(value))
        entries.append(entry)
    if not entries and run.has("cameras"):
        for gt in sorted(run.file("cameras").glob("*.gt.csv")):
            entries.append({"ground_truth": str(run.file(gt.relative_to(run.path)))})
    return entries


def run_visibility(run_dir: str | Path) -> list[TargetVisibility]:
    """Every target seen by every camera of one run."""
    out: list[TargetVisibility] = []
    for e in camera_entries(run_dir):
        if e.get("ground_truth"):
            out.extend(visibility(e["ground_truth"], e.get("rate_hz")))
    return out


def physics_hz_of(run_dir: str | Path) -> float | None:
    """summary.json's physics rate (None: none, or not a rate)."""
    return physics_hz(RunFolder(run_dir).summary() or {})


PASS_COLUMNS = ("vehicle", "camera", "target", "pass", "first_visible_s", "last_visible_s",
                "visible_s", "frames", "overhead_s", "overhead_tick", "overhead_frame",
                "min_eccentricity_deg", "max_angular_size_deg", "min_range_m",
                "screen_direction")


def _fmt(x: float | int | None) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return ""
    if isinstance(x, float):
        return f"{x:.6g}" if abs(x) >= 1e5 else f"{round(x, 6):g}"
    return str(x)


def pass_rows(results: Iterable[TargetVisibility], physics_hz: float | None
              ) -> list[dict[str, str]]:
    """One row per pass (a target never in view gets one row with pass 0)."""
    rows = []
    for tv in results:
        base = {"vehicle": tv.vehicle, "camera": tv.camera, "target": tv.target}
        if not tv.passes:
            rows.append({**base, "pass": "0", "visible_s": "0", "frames": "0"})
        for p in tv.passes:
            tick = round(p.overhead_s * physics_hz) if physics_hz else None
            rows.append({**base, "pass": str(p.index),
                         "first_visible_s": _fmt(p.first_visible_s),
                         "last_visible_s": _fmt(p.last_visible_s),
                         "visible_s": _fmt(p.visible_s), "frames": str(p.frames),
                         "overhead_s": _fmt(p.overhead_s), "overhead_tick": _fmt(tick),
                         "overhead_frame": str(p.overhead_frame),
                         "min_eccentricity_deg": _fmt(p.min_eccentricity_deg),
                         "max_angular_size_deg": _fmt(p.max_angular_size_deg),
                         "min_range_m": _fmt(p.min_range_m),
                         "screen_direction": p.screen_direction})
    return rows


def write_csv(path: str | Path, columns: Sequence[str], rows: Iterable[dict[str, Any]]) -> Path:
    """Write ``rows`` (missing keys left empty) atomically (a symlink at
    ``path`` is replaced, never written through)."""
    p = Path(path)
    with replacing(p) as f:
        w = csv.DictWriter(f, fieldnames=list(columns), restval="", extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    return p


def write_visibility_csv(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """``RUN_DIR/visibility.csv``: one row per pass per target per camera."""
    run = Path(run_dir)
    rows = pass_rows(run_visibility(run), physics_hz_of(run))
    return write_csv(out or run / "visibility.csv", PASS_COLUMNS, rows)
