"""cosim.trials.live_truth: a feed's ground truth keeps every frame (with its
time on screen) and only the rows of targets in view; out-of-view rows are
still checked for their frame and time; the renderer's rows as dicts."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from cosim.errors import ConfigError
from cosim.renderer.truth import GT_COLUMNS
from cosim.trials.live_truth import combine, read_feed_truth, session_truth, target_frame


def _write(path: Path, rows: list[dict[str, object]]) -> Path:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, GT_COLUMNS, restval="")
        w.writeheader()
        w.writerows(rows)
    return path


def _row(frame: int, target: str, in_view: int, **kw: object) -> dict[str, object]:
    return {"frame": frame, "time_s": frame / 10, "vehicle": "v", "camera": "c",
            "target": target, "in_view": in_view, "bbox_x0_px": 1, "bbox_y0_px": 2,
            "bbox_x1_px": 5, "bbox_y1_px": 6, "center_x_px": 3, "center_y_px": 4,
            "pixels_on_target": 9 if in_view else 0, **kw}


def test_frames_kept_rows_in_view_only(tmp_path: Path) -> None:
    rows = [_row(f, t, int(t == "a" and f >= 2)) for f in range(4) for t in ("a", "b")]
    got = read_feed_truth(_write(tmp_path / "g.gt.csv", rows), "v/c")
    assert dict(got.frames["v/c"]) == {0: 0.0, 1: 0.1, 2: 0.2, 3: 0.3}
    assert [(r.frame, r.target, r.bbox_px, r.center_px) for r in got.rows] == [
        (2, "a", (1.0, 2.0, 5.0, 6.0), (3.0, 4.0)), (3, "a", (1.0, 2.0, 5.0, 6.0), (3.0, 4.0))]
    both = combine([got, session_truth([target_frame("w/c", _row(0, "a", 1))])])  # type: ignore[list-item]
    assert set(both.frames) == {"v/c", "w/c"} and len(both.rows) == 3


def test_out_of_view_rows_checked(tmp_path: Path) -> None:
    bad = [_row(0, "a", 0), {**_row(1, "a", 0), "frame": -1}]
    with pytest.raises(ConfigError, match=r"n\.gt\.csv:3: frame: expected a whole number >= 0"):
        read_feed_truth(_write(tmp_path / "n.gt.csv", bad), "f")
    twice = [_row(0, "a", 0), _row(0, "b", 0, time_s=0.5)]
    with pytest.raises(ConfigError, match=r"t\.gt\.csv:3: frame 0 at 0.5 s, on an earlier line "
                                          r"at 0 s"):
        read_feed_truth(_write(tmp_path / "t.gt.csv", twice), "f")
    (tmp_path / "s.gt.csv").write_text(",".join(GT_COLUMNS) + "\n0,0,v\n")
    with pytest.raises(ConfigError, match=r"s\.gt\.csv:2: ground-truth file: 3 fields, 20 in"):
        read_feed_truth(tmp_path / "s.gt.csv", "f")
    for v, msg in (("yes", "in_view: expected a number, got 'yes'"),
                   ("2", "in_view: expected 0 or 1, got '2'")):
        with pytest.raises(ConfigError, match=r"v\.gt\.csv:2: " + msg):
            read_feed_truth(_write(tmp_path / "v.gt.csv", [{**_row(0, "a", 0), "in_view": v}]),
                            "f")


def test_mutated_ground_truth_is_read_or_refused(tmp_path: Path) -> None:
    """Seeded mutations of a valid file (cells replaced by junk, NaN,
    infinities, huge numbers, rows cut short or doubled, bytes that are not
    UTF-8): each is read or refused with a ConfigError naming the file, never
    another exception."""
    import random

    rows = [_row(f, t, int(f % 3 == 0)) for f in range(10) for t in ("a", "b")]
    good = _write(tmp_path / "good.gt.csv", rows).read_bytes()
    junk = ["", "x", "nan", "inf", "-inf", "1e400", "-1", "1.5", "0x10", "\x00", "1,2", '"']
    rng = random.Random(3)
    refused = 0
    for case in range(300):
        lines = good.split(b"\n")
        k = rng.randrange(1, len(lines) - 1)
        cells = lines[k].split(b",")
        how = case % 4
        if how == 0:
            cells[rng.randrange(len(cells))] = rng.choice(junk).encode()
            lines[k] = b",".join(cells)
        elif how == 1:
            lines[k] = b",".join(cells[:rng.randrange(len(cells))])
        elif how == 2:
            lines.insert(k, lines[k].replace(b"0.", b"9.", 1))
        else:
            lines[k] = lines[k][:5] + bytes([rng.randrange(128, 256)]) + lines[k][5:]
        p = tmp_path / f"m{case}.gt.csv"
        p.write_bytes(b"\n".join(lines))
        try:
            read_feed_truth(p, "f")
        except ConfigError as e:
            assert str(p) in str(e), e
            refused += 1
    assert 100 < refused < 300  # most mutations are refused, some are harmless
