"""The files of a trial's clip: its ground truth and its video, read as untrusted.

Owns reading them: a ground-truth CSV's rows of one target (``read_clip_truth``,
one ``GtFrame`` per video frame, and the file's SHA-256), the video's rate,
size, codec and length (``probe_video``, by PyAV), a CSV of bounded fields
with its ``file:line`` errors (``csv_rows``: a sweep's manifest too), a
bounded UTF-8 read of a regular file (``read_bounded``) and whether a path
resolves to a regular file inside given folders (``inside``), with their
limits. Which clips a study has, what it checks across a clip's files (the
video's codec, size, rate and length against the study and the ground truth)
and the trials are ``study``'s.

A ground-truth file is the renderer's ``.gt.csv`` (``cosim.renderer.truth``)
or one made by hand with at least its frame, time, target, in-view, box and
centre columns. Its ``range_m`` and ``eccentricity_deg``, when present and
not empty, give each frame's ``GtFrame.depth_m``: the target centre's
distance along the optical axis, ``range_m * cos(eccentricity_deg)``.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
import stat
from dataclasses import dataclass
from pathlib import Path

from cosim.errors import ConfigError
from cosim.scenario.yaml_lines import read_text_bounded
from cosim.trials.files import file_kind, open_regular

#: bytes of a ground-truth file read for a study
MAX_GT_BYTES = 64 * 1024 * 1024
#: a CSV field (the csv module's own default is 128 KiB)
MAX_FIELD_CHARS = 4096
#: the columns a ground-truth file must have
GT_REQUIRED = ("frame", "time_s", "target", "in_view", "bbox_x0_px", "bbox_y0_px",
               "bbox_x1_px", "bbox_y1_px", "center_x_px", "center_y_px")


@dataclass(frozen=True)
class GtFrame:
    """The clip's target in one video frame (camera pixels, centres at integers)."""

    frame: int
    time_s: float
    in_view: bool
    bbox_px: tuple[float, float, float, float] | None  # x0, y0, x1, y1
    center_px: tuple[float, float] | None
    #: the target centre's distance along the camera's optical axis, ``range_m *
    #: cos(eccentricity_deg)`` of the ground truth (for a level nadir camera: its
    #: height above the target's centre); None: not known (a column absent or empty)
    depth_m: float | None = None


def read_bounded(p: Path, limit: int, what: str) -> str:
    """The UTF-8 text of a regular file of at most ``limit`` bytes."""
    return read_text_bounded(p, limit, what, f"a {what}")


def csv_rows(text: str, p: Path, what: str, required: tuple[str, ...]
             ) -> list[tuple[int, dict[str, str]]]:
    """(line, row) of a CSV text with a header holding ``required``."""
    reader = csv.DictReader(io.StringIO(text, newline=""))
    old = csv.field_size_limit(MAX_FIELD_CHARS)
    try:
        header = reader.fieldnames or []
        missing = [c for c in required if c not in header]
        if missing:
            raise ConfigError(f"{p}:1: not a {what}: missing column(s) {', '.join(missing)}")
        out = []
        for row in reader:
            if None in row or any(v is None for v in row.values()):
                raise ConfigError(f"{p}:{reader.line_num}: {what}: wrong number of fields")
            out.append((reader.line_num, row))
        return out
    except csv.Error as e:
        raise ConfigError(f"{p}:{reader.line_num}: {what}: {e}") from None
    finally:
        csv.field_size_limit(old)


def inside(p: Path, roots: tuple[Path, ...]) -> tuple[Path | None, str]:
    """(``p`` resolved, symlinks followed, "") if it is a regular file inside
    one of ``roots``; else (None, what it is instead, for a message: "" if it
    is missing or outside)."""
    try:
        r = p.resolve(strict=True)
        mode = r.stat().st_mode
    except (OSError, RuntimeError):
        return None, ""
    if not any(r.is_relative_to(root) for root in roots):
        return None, ""
    if not stat.S_ISREG(mode):
        return None, f"; it is {file_kind(mode)}, not a regular file"
    return r, ""


def _num(text: str, p: Path, line: int, col: str) -> float:
    if text == "":
        return math.nan
    try:
        v = float(text)
    except ValueError:
        raise ConfigError(f"{p}:{line}: {col}: expected a number, got {text[:40]!r}") from None
    return v


def _depth_m(r: dict[str, str], p: Path, line: int) -> float | None:
    """``range_m * cos(eccentricity_deg)`` of a ground-truth row; None when
    either is absent or empty. Each value given is checked."""
    rng = r.get("range_m", "")
    ecc = r.get("eccentricity_deg", "")
    rng_m = _num(rng, p, line, "range_m")
    ecc_deg = _num(ecc, p, line, "eccentricity_deg")
    if rng and not (math.isfinite(rng_m) and rng_m >= 0):
        raise ConfigError(f"{p}:{line}: range_m: expected a distance >= 0, got {rng[:40]!r}")
    if ecc and not (math.isfinite(ecc_deg) and 0 <= ecc_deg <= 180):
        raise ConfigError(f"{p}:{line}: eccentricity_deg: expected an angle in [0, 180], "
                          f"got {ecc[:40]!r}")
    if not (rng and ecc):
        return None
    return rng_m * math.cos(math.radians(ecc_deg))


def read_clip_truth(p: Path, target: str | None) -> tuple[str, tuple[GtFrame, ...], str]:
    """The rows of one target of a ground-truth CSV, in frame order, and the
    file's SHA-256 (hex); ``target`` None: the file's only target."""
    text = read_bounded(p, MAX_GT_BYTES, "ground-truth file")
    # the file's own bytes: it was read as strict UTF-8, which encodes back exactly
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
    rows = csv_rows(text, p, "ground-truth file", GT_REQUIRED)
    targets = sorted({r["target"] for _, r in rows})
    if target is None:
        if len(targets) != 1:
            raise ConfigError(f"{p}: ground truth has {len(targets)} targets "
                              f"({', '.join(targets[:10])}); name one with `target:`")
        target = targets[0]
    elif target not in targets:
        raise ConfigError(f"{p}: no target {target!r} in the ground truth (it has: "
                          f"{', '.join(targets[:10]) or 'none'})")
    frames: dict[int, GtFrame] = {}
    for line, r in rows:
        if r["target"] != target:
            continue
        try:
            fno = int(r["frame"])
        except ValueError:
            raise ConfigError(f"{p}:{line}: frame: expected a whole number, "
                              f"got {r['frame'][:40]!r}") from None
        if fno in frames:
            raise ConfigError(f"{p}:{line}: frame {fno} of target {target!r} given twice")
        vals = [_num(r[c], p, line, c) for c in GT_REQUIRED[4:]]
        in_view = _num(r["in_view"], p, line, "in_view")
        bbox = tuple(vals[:4]) if all(math.isfinite(v) for v in vals[:4]) else None
        centre = tuple(vals[4:]) if all(math.isfinite(v) for v in vals[4:]) else None
        frames[fno] = GtFrame(frame=fno, time_s=_num(r["time_s"], p, line, "time_s"),
                              in_view=in_view == 1.0, bbox_px=bbox,  # type: ignore[arg-type]
                              center_px=centre,  # type: ignore[arg-type]
                              depth_m=_depth_m(r, p, line))
    return target, tuple(frames[k] for k in sorted(frames)), digest


def probe_video(p: Path) -> tuple[float, int, int, str, int, int]:
    """(rate_hz, width_px, height_px, codec, frames: 0 if the file does not
    say, size in bytes) of a video file, read by PyAV."""
    f = open_regular(p)
    try:
        import av

        size = os.fstat(f.fileno()).st_size
        with av.open(f) as c:
            s = c.streams.video[0]
            rate = s.average_rate or s.guessed_rate
            if not rate:
                raise ValueError("no frame rate")
            cc = s.codec_context
            return (float(rate), int(cc.width), int(cc.height), str(cc.name),
                    int(s.frames or 0), size)
    except Exception as e:  # noqa: BLE001 - any failure is "cannot read this video"
        raise ConfigError(f"{p}: cannot read it as a video ({e})") from None
    finally:
        f.close()
