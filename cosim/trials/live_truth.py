"""The ground truth of a live session's feeds, as its scoring needs it.

Owns reading it: a feed's ground-truth CSV (the renderer's ``.gt.csv``,
``cosim.renderer.truth.GT_COLUMNS``, with a downlink's
``datalink.DELIVERED_COLUMNS``) or a run folder's feeds, into a
``SessionTruth``: each feed's frames (frame number -> time on screen) and
the rows of the targets in view (``TargetFrame``); a row out of view carries
nothing scoring uses and is not kept, which keeps an hour of 16 feeds small.
A feed with a downlink shows only its delivered frames: its frames are those
with a ``delivered_time_s``, each on screen from then, and its targets'
pixels are the delivered ``delivered_pixels_on_target``.

The files are untrusted: a regular UTF-8 file of at most
``clips.MAX_GT_BYTES``, every value used checked (``ConfigError`` with its
file:line otherwise). The rules that score reports are ``live_scoring``'s.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.conspicuity.visibility import camera_entries
from cosim.errors import ConfigError
from cosim.trials.clips import MAX_FIELD_CHARS, MAX_GT_BYTES, read_bounded

#: the columns a live feed's ground-truth file must have
LIVE_GT_REQUIRED = ("frame", "time_s", "target", "in_view", "bbox_x0_px", "bbox_y0_px",
                    "bbox_x1_px", "bbox_y1_px", "center_x_px", "center_y_px",
                    "pixels_on_target")
#: the largest |value| of a ground-truth number (a coordinate, a time) kept
MAX_GT_VALUE = 1e9


@dataclass(frozen=True, slots=True)
class TargetFrame:
    """One target in one frame of one feed, as the ground truth has it."""

    feed: str
    frame: int
    #: when the frame is on screen (s): its ``time_s``, or with a downlink its ``delivered_time_s``
    time_s: float
    target: str
    in_view: bool
    bbox_px: tuple[float, float, float, float] | None  # x0, y0, x1, y1
    center_px: tuple[float, float] | None
    pixels_on_target: float  # with a downlink: delivered; NaN: not known
    visible_fraction: float = math.nan  # NaN: not known


@dataclass(frozen=True)
class SessionTruth:
    """A session's feeds: each one's frames (frame number -> time on screen,
    s) and the rows of targets in view in them."""

    frames: Mapping[str, Mapping[int, float]]
    rows: tuple[TargetFrame, ...]

    def __iter__(self) -> Iterator[TargetFrame]:
        """The rows of targets in view (those out of view were not kept)."""
        return iter(self.rows)


def session_truth(rows: Iterable[TargetFrame]) -> SessionTruth:
    """The ``SessionTruth`` of ground-truth rows (every row's frame is one of
    its feed's; the rows in view are kept)."""
    frames: dict[str, dict[int, float]] = {}
    kept = []
    for t in rows:
        frames.setdefault(t.feed, {})[t.frame] = t.time_s
        if t.in_view:
            kept.append(t)
    return SessionTruth(frames, tuple(kept))


def combine(parts: Iterable[SessionTruth]) -> SessionTruth:
    """Several feeds' ground truth as one session's."""
    frames: dict[str, dict[int, float]] = {}
    rows: list[TargetFrame] = []
    for p in parts:
        for feed, fr in p.frames.items():
            frames.setdefault(feed, {}).update(fr)
        rows.extend(p.rows)
    return SessionTruth(frames, tuple(rows))


def _number(v: Any, what: str) -> float:
    """A ground-truth value: NaN for empty/None, else a finite number within
    +-``MAX_GT_VALUE`` (ValueError otherwise)."""
    if v is None or v == "":
        return math.nan
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number, got {str(v)[:40]!r}") from None
    if not (math.isfinite(x) and abs(x) <= MAX_GT_VALUE):
        raise ValueError(f"{what}: expected a finite number within +-{MAX_GT_VALUE:g}, "
                         f"got {str(v)[:40]!r}")
    return x


def _frame_time(frame_v: Any, shown_v: Any, link: bool) -> tuple[int, float | None]:
    """(frame number, time on screen: ``shown_v``, the row's ``time_s`` or with
    a downlink its ``delivered_time_s``, None for a frame it did not deliver)."""
    frame = _number(frame_v, "frame")
    if not (frame >= 0 and frame == int(frame)):
        raise ValueError(f"frame: expected a whole number >= 0, got {str(frame_v)[:40]!r}")
    if link and shown_v in ("", None):
        return int(frame), None
    time_s = _number(shown_v, "delivered_time_s" if link else "time_s")
    if not time_s >= 0:
        raise ValueError(f"time_s: expected a time >= 0, got {time_s!r}")
    return int(frame), time_s


def _in_view(v: Any) -> bool:
    x = _number(v, "in_view")
    if x not in (0.0, 1.0):
        raise ValueError(f"in_view: expected 0 or 1, got {str(v)[:40]!r}")
    return x == 1.0


def target_frame(feed: str, row: Mapping[str, Any]) -> TargetFrame | None:
    """A ground-truth row (``truth.GT_COLUMNS``, values as numbers or as the
    CSV's text) as a ``TargetFrame``; None for a frame a downlink did not
    deliver (a row with ``delivered_time_s`` empty). ValueError naming the
    column for a bad value."""
    link = "delivered_time_s" in row
    frame, time_s = _frame_time(row["frame"], row["delivered_time_s" if link else "time_s"],
                                link)
    if time_s is None:
        return None
    box = tuple(_number(row[c], c) for c in ("bbox_x0_px", "bbox_y0_px", "bbox_x1_px",
                                              "bbox_y1_px"))
    ctr = tuple(_number(row[c], c) for c in ("center_x_px", "center_y_px"))
    px = _number(row["delivered_pixels_on_target" if link else "pixels_on_target"],
                 "pixels_on_target")
    return TargetFrame(feed=feed, frame=frame, time_s=time_s, target=str(row["target"]),
                       in_view=_in_view(row["in_view"]),
                       bbox_px=box if all(map(math.isfinite, box)) else None,  # type: ignore[arg-type]
                       center_px=ctr if all(map(math.isfinite, ctr)) else None,  # type: ignore[arg-type]
                       pixels_on_target=px,
                       visible_fraction=_number(row.get("visible_fraction"), "visible_fraction"))


def read_feed_truth(path: str | Path, feed: str) -> SessionTruth:
    """One feed's ground-truth CSV as a ``SessionTruth``. Rows out of view
    are checked for their frame and time only (all they give)."""
    p = Path(path)
    text = read_bounded(p, MAX_GT_BYTES, "ground-truth file")
    reader = csv.reader(io.StringIO(text, newline=""))
    old = csv.field_size_limit(MAX_FIELD_CHARS)
    frames: dict[int, float] = {}
    rows: list[TargetFrame] = []
    try:
        header = next(reader, [])
        missing = [c for c in LIVE_GT_REQUIRED if c not in header]
        if missing:
            raise ConfigError(f"{p}:1: not a ground-truth file: missing column(s) "
                              f"{', '.join(missing)}")
        link = "delivered_time_s" in header
        i_frame, i_view = header.index("frame"), header.index("in_view")
        i_shown = header.index("delivered_time_s" if link else "time_s")
        for fields in reader:
            if len(fields) != len(header):
                raise ConfigError(f"{p}:{reader.line_num}: ground-truth file: "
                                  f"{len(fields)} fields, {len(header)} in the header")
            try:
                frame, time_s = _frame_time(fields[i_frame], fields[i_shown], link)
                if time_s is None:
                    continue
                if frames.setdefault(frame, time_s) != time_s:
                    raise ValueError(f"frame {frame} at {time_s:g} s, on an earlier line at "
                                     f"{frames[frame]:g} s")
                if fields[i_view] != "0" and _in_view(fields[i_view]):
                    tf = target_frame(feed, dict(zip(header, fields)))
                    assert tf is not None
                    rows.append(tf)
            except ValueError as e:
                raise ConfigError(f"{p}:{reader.line_num}: {e}") from None
    except csv.Error as e:
        raise ConfigError(f"{p}:{reader.line_num}: ground-truth file: {e}") from None
    finally:
        csv.field_size_limit(old)
    return SessionTruth({feed: frames}, tuple(rows))


def read_run_truth(run_dir: str | Path, feeds: Sequence[str]) -> SessionTruth:
    """The ground truth of the named feeds (``VEHICLE/CAMERA``) of a run
    folder, from its summary's camera streams; a feed the run has no
    ground truth for is a ``ConfigError`` naming those it has."""
    files = {f"{e.get('vehicle')}/{e.get('camera')}": e.get("ground_truth")
             for e in camera_entries(run_dir)}
    parts = []
    for feed in feeds:
        path = files.get(feed)
        if not path:
            raise ConfigError(f"{run_dir}: no ground truth for feed {feed!r}; the run has: "
                              f"{', '.join(sorted(k for k, v in files.items() if v)[:20])}")
        parts.append(read_feed_truth(path, feed))
    return combine(parts)
