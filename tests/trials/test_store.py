"""Trials without a browser: the study file, the measures, the response store."""

from __future__ import annotations

import csv
import math
import os
import re
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from cosim.core.display import DisplayProfile
from cosim.errors import ConfigError
from cosim.renderer.video import open_video
from cosim.trials.clips import GT_REQUIRED
from cosim.trials.measures import measures_at, participant_display
from cosim.trials.store import EXPORT_COLUMNS, Store, export_csv
from cosim.trials.study import load_study, williams_row

GT_HEADER = ("frame,time_s,vehicle,camera,target,in_view,fully_in_view,bbox_x0_px,bbox_y0_px,"
             "bbox_x1_px,bbox_y1_px,center_x_px,center_y_px,eccentricity_px,eccentricity_deg,"
             "angular_size_deg,pixels_on_target,range_m,contrast")


def write_gt(path: Path, rows: list[tuple[int, float, float, int]], target: str = "truck",
             half: tuple[float, float] = (10.0, 5.0),
             range_ecc: dict[int, tuple[str, str]] | None = None) -> Path:
    """A ground truth: (frame, centre x, centre y, in_view) with a bbox of ``half`` sizes;
    ``range_ecc``: the range_m and eccentricity_deg cells of some frames (else empty)."""
    lines = [GT_HEADER]
    hx, hy = half
    for f, cx, cy, iv in rows:
        rng, ecc = (range_ecc or {}).get(f, ("", ""))
        lines.append(f"{f},{f / 10:.6f},uav,nadir,{target},{iv},{iv},{cx - hx},{cy - hy},"
                     f"{cx + hx},{cy + hy},{cx},{cy},,{ecc},,,{rng},")
    path.write_text("\n".join(lines) + "\n")
    return path


_VIDEOS: dict[str, bytes] = {}


def write_video(path: Path, codec: str = "h264") -> Path:
    """A 320 x 240, 5-frame, 10 Hz video (encoded once per codec)."""
    if codec not in _VIDEOS:
        tmp = path.with_name(f"_{codec}.mp4")
        sink = open_video(str(tmp), codec, 10.0, 320, 240)
        for k in range(5):
            sink.write(np.full((240, 320, 3), 40 * k, np.uint8))
        sink.release()
        _VIDEOS[codec] = tmp.read_bytes()
        tmp.unlink()
    path.write_bytes(_VIDEOS[codec])
    return path


def write_study(folder: Path, body: str, clips: int = 2) -> Path:
    for i in range(clips):
        write_video(folder / f"c{i}.mp4")
        write_gt(folder / f"c{i}.gt.csv", [(f, 159.5 + 10 * f, 119.5, 1) for f in range(5)])
    p = folder / "study.yaml"
    p.write_text(body)
    return p


CLIPS = """\
clips:
  - {video: c0.mp4, ground_truth: c0.gt.csv, rate_hz: 10, width_px: 320, height_px: 240,
     conditions: {speed_kt: 50, alt_agl_m: 100, target: truck}}
  - {video: c1.mp4, ground_truth: c1.gt.csv, rate_hz: 10, width_px: 320, height_px: 240,
     conditions: {speed_kt: 100, alt_agl_m: 30.0, target: truck}}
"""


# --- study ---

def test_study_reads_clips_and_orders_trials(tmp_path: Path) -> None:
    p = write_study(tmp_path, "name: s\nprotocol: disappear\npractice: 1\nbreak_every: 2\n"
                              "repeats: 2\norder: shuffle\nseed: 7\n" + CLIPS)
    st = load_study(p)
    assert [c.id for c in st.clips] == ["clip0", "clip1"]
    assert st.clips[1].condition_map == {"speed_kt": "100", "alt_agl_m": "30", "target": "truck"}
    assert st.clips[0].target == "truck" and len(st.clips[0].frames) == 5
    trials = st.trial_order(0)
    assert [t.practice for t in trials] == [True, False, False, False, False]
    assert [t.break_before for t in trials] == [False, False, False, True, False]
    assert sorted(t.clip for t in trials[1:]) == [0, 0, 1, 1]
    assert trials == st.trial_order(0)  # the seed decides


def test_williams_square_is_balanced() -> None:
    for n in (4, 5):
        rows = [williams_row(n, r) for r in range(n if n % 2 == 0 else 2 * n)]
        for pos in range(n):  # every clip at every position equally often
            counts = [sum(r[pos] == c for r in rows) for c in range(n)]
            assert len(set(counts)) == 1, (n, pos, counts)
        pairs: dict[tuple[int, int], int] = {}
        for r in rows:  # every clip after every other equally often
            for a, b in zip(r, r[1:]):
                pairs[(a, b)] = pairs.get((a, b), 0) + 1
        assert len(pairs) == n * (n - 1) and len(set(pairs.values())) == 1, (n, pairs)


@pytest.mark.parametrize("body, match", [
    ("protocol: disappear\nspeed: 3\n" + CLIPS, r"study\.yaml:2: speed: unknown key"),
    ("protocol: blink\n" + CLIPS, r"study\.yaml:1: protocol: expected one of: disappear, "
                                  r"recognise, track, live; got 'blink'"),
    ("protocol: disappear\n", r"study\.yaml:1: \(top level\): missing the clips"),
    ("protocol: disappear\npractice: -1\n" + CLIPS, r"study\.yaml:2: practice: must be >= 0"),
    ("protocol: disappear\nclips:\n  - {video: c0.mp4, ground_truth: c0.gt.csv, fps: 3}\n",
     r"study\.yaml:3: clips\[0\]\.fps: unknown key"),
    ("protocol: disappear\nprotocol: recognise\n" + CLIPS, r"study\.yaml:2: protocol: duplicate"),
    ("protocol: [disappear\n", r"study\.yaml:\d+: YAML syntax error"),
])
def test_study_errors_name_file_and_line(tmp_path: Path, body: str, match: str) -> None:
    p = write_study(tmp_path, body)
    with pytest.raises(ConfigError, match=match):
        load_study(p)


def test_study_reports_every_problem_at_once(tmp_path: Path) -> None:
    p = write_study(tmp_path, "protocol: blink\norder: random\nseed: x\n" + CLIPS)
    with pytest.raises(ConfigError) as e:
        load_study(p)
    assert [m.split(":")[1] for m in e.value.problems] == ["1", "2", "3"]


def test_ground_truth_errors_name_their_line(tmp_path: Path) -> None:
    p = write_study(tmp_path, "protocol: disappear\n" + CLIPS)
    gt = tmp_path / "c1.gt.csv"
    lines = gt.read_text().splitlines()
    fields = lines[3].split(",")
    fields[7] = "abc"  # bbox_x0_px of file line 4
    lines[3] = ",".join(fields)
    gt.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match=r"study\.yaml:\d+: clips\[1\]: .*c1\.gt\.csv:4: "
                                          r"bbox_x0_px: expected a number, got 'abc"):
        load_study(p)


def test_ground_truth_gives_the_targets_depth_along_the_optical_axis(tmp_path: Path) -> None:
    """depth_m = range_m * cos(eccentricity_deg); None where a cell is empty or
    the file has no such columns (older and hand-made ground truths); the
    measures carry it (a track trial: its still frame's)."""
    from cosim.trials.measures import track_measures

    p = write_study(tmp_path, "protocol: disappear\n" + CLIPS)
    # the target crosses the centre at frame 2; 40, 50, ... m away, 60 deg off the axis
    write_gt(tmp_path / "c0.gt.csv", [(f, 139.5 + 10 * f, 119.5, 1) for f in range(5)],
             range_ecc={f: (f"{40 + 10 * f}", "60") for f in range(4)} | {4: ("80", "")})
    hand = tmp_path / "c1.gt.csv"  # only the columns a ground truth needs
    with open(hand, newline="") as f:
        rows = list(csv.DictReader(f))
    hand.write_text("\n".join([",".join(GT_REQUIRED)] + [
        ",".join(r[c] for c in GT_REQUIRED) for r in rows]) + "\n")
    c0, c1 = load_study(p).clips
    assert [g.depth_m for g in c0.frames[:4]] == pytest.approx([20.0, 25.0, 30.0, 35.0])
    assert c0.frames[4].depth_m is None  # an empty cell: not known
    assert [g.depth_m for g in c1.frames] == [None] * 5
    d = participant_display(screen_width_px=1600, screen_height_px=900, screen_width_mm=400,
                            screen_height_mm=225, viewing_distance_mm=500)
    assert measures_at(c0, 3, d).target_depth_m == pytest.approx(35.0)
    assert measures_at(c1, 3, d).target_depth_m is None
    assert c0.still_frame == 2
    assert track_measures(c0, d, (1.0, 0.0), 2.0, 800.0).target_depth_m == pytest.approx(30.0)
    assert track_measures(c1, d, (1.0, 0.0), 2.0, 800.0).target_depth_m is None


@pytest.mark.parametrize("range_ecc, match", [
    (("-1", "10"), r"range_m: expected a distance >= 0, got '-1'"),
    (("inf", "10"), r"range_m: expected a distance >= 0, got 'inf'"),
    (("far", "10"), r"range_m: expected a number, got 'far'"),
    (("50", "180.5"), r"eccentricity_deg: expected an angle in \[0, 180\], got '180\.5'"),
    (("50", "nan"), r"eccentricity_deg: expected an angle in \[0, 180\], got 'nan'"),
    (("", "-3"), r"eccentricity_deg: expected an angle in \[0, 180\], got '-3'"),
])
def test_ground_truth_range_and_eccentricity_are_checked(
        tmp_path: Path, range_ecc: tuple[str, str], match: str) -> None:
    p = write_study(tmp_path, "protocol: disappear\n" + CLIPS)
    write_gt(tmp_path / "c1.gt.csv", [(f, 159.5, 119.5, 1) for f in range(5)],
             range_ecc={2: range_ecc})
    with pytest.raises(ConfigError, match=r"study\.yaml:\d+: clips\[1\]: .*c1\.gt\.csv:4: "
                                          + match):
        load_study(p)


def test_ground_truth_target_must_exist(tmp_path: Path) -> None:
    p = write_study(tmp_path, "protocol: disappear\nclips:\n  - {video: c0.mp4, ground_truth: "
                              "c0.gt.csv, target: bus, rate_hz: 10, width_px: 8, height_px: 8}\n")
    with pytest.raises(ConfigError, match=r"no target 'bus' in the ground truth \(it has: truck"):
        load_study(p)


@pytest.mark.parametrize("video", ["../outside.mp4", "/etc/passwd", "link.mp4", "sub"])
def test_clip_files_must_be_inside_the_study_folder(tmp_path: Path, video: str) -> None:
    study_dir = tmp_path / "study"
    study_dir.mkdir()
    (tmp_path / "outside.mp4").write_bytes(b"x")
    os.symlink(tmp_path / "outside.mp4", study_dir / "link.mp4")
    (study_dir / "sub").mkdir()
    p = write_study(study_dir, f"protocol: disappear\nclips:\n  - {{video: {video}, ground_truth: "
                               f"c0.gt.csv, rate_hz: 10, width_px: 8, height_px: 8}}\n")
    with pytest.raises(ConfigError, match=r"study\.yaml:3: clips\[0\]\.video: .* must be an "
                                          r"existing file inside the study's folders"):
        load_study(p)


def _sweep(folder: Path, video: str) -> None:
    (folder / "run_0000" / "cameras").mkdir(parents=True)
    write_video(folder / "run_0000" / "cameras" / "uav_nadir.mp4")
    write_gt(folder / "run_0000" / "cameras" / "uav_nadir.gt.csv",
             [(f, 100.0, 100.0, 1) for f in range(5)], target="fire_truck")
    (folder / "manifest.csv").write_text(
        "speed_kt,alt_agl_m,target,run,vehicle,camera,video,ground_truth,frames,rate_hz,"
        "width_px,height_px,hfov_deg,vfov_deg\n"
        f"50,30,fire_truck,run_0000,uav,nadir,{video},run_0000/cameras/uav_nadir.gt.csv,5,10,"
        "320,240,48.7,37.6\n")


def test_sweep_folder_clips(tmp_path: Path) -> None:
    _sweep(tmp_path / "exp2", "run_0000/cameras/uav_nadir.mp4")
    p = tmp_path / "study.yaml"
    p.write_text("protocol: recognise\nsweep: {folder: exp2, where: {speed_kt: 50}}\n")
    st = load_study(p)
    (c,) = st.clips
    assert (c.id, c.run, c.target, c.rate_hz, c.width_px) == (
        "run_0000/uav_nadir", "run_0000", "fire_truck", 10.0, 320)
    assert c.condition_map == {"speed_kt": "50", "alt_agl_m": "30", "target": "fire_truck"}
    assert (tmp_path / "exp2").resolve() in st.roots


def test_sweep_manifest_cannot_point_outside(tmp_path: Path) -> None:
    _sweep(tmp_path / "exp2", "../../../etc/passwd")
    p = tmp_path / "study.yaml"
    p.write_text("protocol: disappear\nsweep: exp2\n")
    with pytest.raises(ConfigError, match=r"study\.yaml:2: sweep: .*manifest\.csv:2: video "
                                          r"'\.\./\.\./\.\./etc/passwd' must be an existing file "
                                          r"inside the sweep folder"):
        load_study(p)


def test_videos_must_play_in_browsers_and_match_their_size(tmp_path: Path) -> None:
    p = write_study(tmp_path, "protocol: disappear\n" + CLIPS)
    write_video(tmp_path / "c1.mp4", codec="mp4v")
    with pytest.raises(ConfigError, match=r"study\.yaml:\d+: clips\[1\]: .*c1\.mp4: codec "
                                          r"mpeg4 does not play in browsers; .*codec: h264"):
        load_study(p)
    p.write_text(p.read_text().replace("width_px: 320", "width_px: 640", 1))
    write_video(tmp_path / "c1.mp4")
    with pytest.raises(ConfigError, match=r"clips\[0\]: .*c0\.mp4: the video is 320 x 240 px, "
                                          r"not 640 x 240"):
        load_study(p)
    # the rate maps a key press to a frame: a wrong one is refused, as a short ground truth
    p.write_text(p.read_text().replace("width_px: 640", "width_px: 320", 1)
                 .replace("rate_hz: 10", "rate_hz: 12", 1))
    with pytest.raises(ConfigError, match=r"clips\[0\]: .*c0\.mp4: the video runs at 10 "
                                          r"frames/s, not 12"):
        load_study(p)
    p.write_text(p.read_text().replace("rate_hz: 12", "rate_hz: 10", 1))
    write_gt(tmp_path / "c0.gt.csv", [(f, 159.5, 119.5, 1) for f in range(2)])
    with pytest.raises(ConfigError, match=r"c0\.mp4: 5 frames, but .*c0\.gt\.csv has 2"):
        load_study(p)
    write_gt(tmp_path / "c0.gt.csv", [(f, 159.5, 119.5, 1) for f in range(5)])
    (tmp_path / "c0.mp4").write_bytes(b"not a video")
    with pytest.raises(ConfigError, match=r"clips\[0\]: .*c0\.mp4: cannot read it as a video"):
        load_study(p)


# --- measures ---

def test_measures_by_hand(tmp_path: Path) -> None:
    # a 320 x 240 video on a 1600 x 900 px, 400 x 225 mm screen: drawn 3.75x (900 / 240),
    # 1200 px wide with 200 px bars left and right; 0.25 mm a screen pixel; eye 500 mm away
    p = write_study(tmp_path, "protocol: disappear\n" + CLIPS)
    write_gt(tmp_path / "c0.gt.csv", [(0, 159.5, 119.5, 1), (1, 199.5, 99.5, 1),
                                      (2, 400.0, 99.5, 0), (3, 400.0, 99.5, 0),
                                      (4, 400.0, 99.5, 0)])
    clip = load_study(p).clips[0]
    d = participant_display(screen_width_px=1600, screen_height_px=900, screen_width_mm=400,
                            screen_height_mm=225, viewing_distance_mm=500)
    assert isinstance(d, DisplayProfile)  # the one display geometry (cosim.core.display)
    assert d.scale(320, 240) == 3.75
    assert d.camera_to_screen_mm(320, 240, -0.5, -0.5) == (-150.0, -112.5)  # image corner
    m0 = measures_at(clip, 0, d)  # the target at the image centre = the fixation mark
    assert (m0.frame, m0.onscreen_distance_mm, m0.eccentricity_deg) == (0, 0.0, 0.0)
    # its bbox 20 x 10 camera px = 18.75 x 9.375 mm, centred: 2 atan(half diagonal / 500)
    assert m0.target_angular_size_deg == pytest.approx(
        2 * math.degrees(math.atan(math.hypot(9.375, 4.6875) / 500)), rel=1e-12)
    m1 = measures_at(clip, 1, d)  # 40 px right, 20 px up: 150 x 75 screen px = 37.5, 18.75 mm
    assert (m1.screen_x_mm, m1.screen_y_mm) == (37.5, -18.75)
    assert m1.onscreen_distance_mm == pytest.approx(18.75 * math.sqrt(5), rel=1e-12)
    assert m1.eccentricity_deg == pytest.approx(
        math.degrees(math.atan(18.75 * math.sqrt(5) / 500)), rel=1e-12)
    m2 = measures_at(clip, 2, d)  # out of view: a position, no size
    assert m2.target_in_view is False and m2.target_angular_size_deg is None
    assert clip.frame_at(0.149) == 1 and clip.frame_at(0.151) == 2
    assert clip.frame_at(9.0) == 4 and clip.frame_at(-0.2) == 0  # clamped to the clip


def test_display_profile_is_checked() -> None:
    with pytest.raises(ConfigError, match=r"viewing_distance_mm must be a number in"):
        participant_display(screen_width_px=1920, screen_height_px=1080, screen_width_mm=500,
                            screen_height_mm=280, viewing_distance_mm=0)


# --- store ---

DISPLAY = {"screen_width_px": 1920, "screen_height_px": 1080, "screen_width_mm": 531.0,
           "screen_height_mm": 299.0, "viewing_distance_mm": 600.0}


def _response(session: str, trial: int, **kw: object) -> dict[str, object]:
    return {"session": session, "participant": "p01", "trial_index": trial, "kind": "disappear",
            "practice": trial == 0, "protocol": "disappear", "clip": "run_0000/uav_nadir",
            "run": "run_0000", "conditions": "{}", "condition_speed_kt": "50",
            "condition_alt_agl_m": "30", "condition_target": "truck", "key": "space",
            "frame": 12, "video_time_s": 0.4, "reaction_time_ms": 412.5,
            "target_in_view": True, "eccentricity_deg": 3.25, "onscreen_distance_mm": 34.1,
            "target_angular_size_deg": 0.5, "recognised": None, **DISPLAY, **kw}


def test_responses_are_stored_once_and_exported(tmp_path: Path) -> None:
    db = tmp_path / "trials.sqlite"
    with Store(db) as store:
        s = store.create_session(participant="p01", study="s", protocol="disappear",
                                 display=DISPLAY, order_method="shuffle", seed=7,
                                 session_number=0, trial_order=[{"index": 0}, {"index": 1}])
        sid = s["id"]
        assert s["trial_order"] == [{"index": 0}, {"index": 1}] and s["state"] == "ready"
        row, created = store.record_response(_response(sid, 0, target_depth_m=28.25))
        assert created and row["frame"] == 12 and row["target_depth_m"] == 28.25
        again, created = store.record_response(_response(sid, 0, frame=99, key="x"))
        assert not created and again["frame"] == 12 and again["id"] == row["id"]  # first wins
        store.record_response(_response(sid, 1, key="none", frame=None, video_time_s=None,
                                        reaction_time_ms=None, target_in_view=None,
                                        eccentricity_deg=None, onscreen_distance_mm=None,
                                        target_angular_size_deg=None))
        assert len(store.responses(sid)) == 2
        assert store.sessions()[0]["answered"] == 2
    out = export_csv(db, tmp_path / "responses.csv")  # a path: opens its own store
    with out.open(newline="") as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == EXPORT_COLUMNS
    assert EXPORT_COLUMNS == (
        "session", "participant", "trial_index", "practice", "protocol", "clip", "run",
        "condition_speed_kt", "condition_alt_agl_m", "condition_target", "frame",
        "video_time_s", "reaction_time_ms", "key", "target_in_view", "eccentricity_deg",
        "onscreen_distance_mm", "target_angular_size_deg", "camera_gap_deg", "target_depth_m",
        "viewing_distance_mm", "screen_width_mm", "screen_height_mm", "screen_width_px",
        "screen_height_px", "recognised", "reshown")
    first = dict(zip(rows[0], rows[1]))
    assert first == {
        "session": sid, "participant": "p01", "trial_index": "0", "practice": "1",
        "protocol": "disappear", "clip": "run_0000/uav_nadir", "run": "run_0000",
        "condition_speed_kt": "50", "condition_alt_agl_m": "30", "condition_target": "truck",
        "frame": "12", "video_time_s": "0.4", "reaction_time_ms": "412.5", "key": "space",
        "target_in_view": "1", "eccentricity_deg": "3.25", "onscreen_distance_mm": "34.1",
        "target_angular_size_deg": "0.5", "viewing_distance_mm": "600.0",
        "screen_width_mm": "531.0", "screen_height_mm": "299.0", "screen_width_px": "1920",
        "screen_height_px": "1080", "recognised": "", "camera_gap_deg": "",
        "target_depth_m": "28.25", "reshown": ""}
    second = dict(zip(rows[0], rows[2]))
    assert (second["practice"], second["frame"], second["target_in_view"], second["key"],
            second["target_depth_m"]) == ("0", "", "", "none", "")
    assert len(rows) == 3


def test_store_url_and_bad_url(tmp_path: Path) -> None:
    with Store(f"sqlite:///{tmp_path / 'u.sqlite'}") as store:
        assert store.sessions() == []
    with pytest.raises(ConfigError, match=r"cannot open the trial database nosuch://x"):
        Store("nosuch://x")


def test_a_database_that_is_not_a_regular_file_is_refused(tmp_path: Path) -> None:
    """A FIFO (or a folder) where the database should be: said so, by path or
    by URL (SQLite had said "disk I/O error")."""
    fifo = tmp_path / "f.sqlite"
    os.mkfifo(fifo)
    for db in (fifo, f"sqlite:///{fifo}"):
        with pytest.raises(ConfigError, match=rf"cannot open the trial database "
                                              rf"{re.escape(str(db))}: it is a FIFO, not a "
                                              rf"regular file"):
            Store(db)
    (tmp_path / "d.sqlite").mkdir()
    with pytest.raises(ConfigError, match=r"d\.sqlite: it is a folder, not a regular file"):
        Store(tmp_path / "d.sqlite")


def test_a_database_from_an_older_cosim_gains_the_new_columns(tmp_path: Path) -> None:
    """A database made before camera_gap_deg, target_depth_m and reshown
    existed opens, keeps its rows (the new cells empty) and takes new
    responses with them."""
    db = tmp_path / "old.sqlite"
    with Store(db) as store:
        s = store.create_session(participant="p01", study="s", protocol="disappear",
                                 display=DISPLAY, order_method="shuffle", seed=7,
                                 session_number=0, trial_order=[{"index": 0}, {"index": 1}])
        store.record_response(_response(s["id"], 0))
    con = sqlite3.connect(db)  # make it old: SQLite >= 3.35 drops columns
    con.execute("ALTER TABLE responses DROP COLUMN camera_gap_deg")
    con.execute("ALTER TABLE responses DROP COLUMN reshown")
    con.execute("ALTER TABLE responses DROP COLUMN target_depth_m")
    con.commit()
    con.close()
    with Store(db) as store:
        old = store.responses(s["id"])
        assert len(old) == 1 and old[0]["camera_gap_deg"] is None and old[0]["reshown"] is None
        assert old[0]["target_depth_m"] is None
        row, created = store.record_response(_response(s["id"], 1, camera_gap_deg=12.5,
                                                       target_depth_m=98.25, reshown=True))
        assert created and row["camera_gap_deg"] == 12.5 and row["reshown"] is True
        assert row["target_depth_m"] == 98.25


@pytest.mark.parametrize("north_m,east_m", [(0.0, 0.0), (12.0, -7.0), (-30.0, 21.0)])
def test_camera_gap_is_the_renderers_angle_and_the_ground_distance(
        tmp_path: Path, north_m: float, east_m: float) -> None:
    """camera_gap_deg of a frame rendered from a level nadir camera 100 m up:
    the renderer's own angle off the optical axis (from its 3-D vectors);
    target_depth_m, read from the rendered ground truth, is the camera's
    height above the target's centre, and tan(gap) * target_depth_m is the
    target's distance on the ground from the point under the camera."""
    from cosim.core.camera import CameraSpec, camera_pose
    from cosim.renderer.frame import World, WorldSpec, render_frame
    from cosim.renderer.truth import GT_COLUMNS
    from cosim.trials.clips import read_clip_truth
    from cosim.trials.study import Clip
    from cosim.world.ground import GroundSpec
    from cosim.world.targets import TARGET_DEFAULTS, TargetSpec

    lat, lon, ground = 37.0, -122.0, 10.0
    length, width, height, colour = TARGET_DEFAULTS["truck"]
    t = TargetSpec("t", "truck", north_m, east_m, None, None, 0.0, length, width, height, colour)
    cam = CameraSpec("c", (0,), "nadir", -90.0, False, 60.0, 2 * math.degrees(
        math.atan(math.tan(math.radians(30.0)) * 240 / 320)), 320, 240, 10.0, 12)
    pose = camera_pose(cam, lat, lon, ground + 100.0, 0.0, 0.0, 0.0, ground_alt_m=ground)
    _, (row,) = render_frame(World(WorldSpec(lat, lon, ground, 1, 120.0, GroundSpec(), (t,))),
                             cam, pose, 0)
    # the renderer's ground-truth row, every value at full precision
    row = {**row, "frame": 0, "time_s": 0.0, "vehicle": "uav", "camera": "c", "target": "t"}
    gt = tmp_path / "g.csv"
    with open(gt, "w", newline="") as f:
        csv.writer(f).writerows([GT_COLUMNS, ["" if row[c] is None else repr(row[c])
                                              if isinstance(row[c], float) else row[c]
                                              for c in GT_COLUMNS]])
    _, frames, _ = read_clip_truth(gt, "t")
    clip = Clip(id="c", video=tmp_path / "v.mp4", ground_truth=gt, target="t", run="",
                rate_hz=10.0, width_px=320, height_px=240, conditions=(), frames=frames,
                hfov_deg=60.0)
    d = participant_display(screen_width_px=1600, screen_height_px=900, screen_width_mm=400,
                            screen_height_mm=225, viewing_distance_mm=500)
    m = measures_at(clip, 0, d)
    assert m.camera_gap_deg == pytest.approx(row["eccentricity_deg"], abs=1e-6)
    # the target stands on the curved Earth, r**2 / 2R below the camera's level
    # (0.1 mm at 37 m): its depth is the height above its centre plus that
    r_m = math.hypot(north_m, east_m)
    assert m.target_depth_m == pytest.approx(100.0 - height / 2 + r_m**2 / (2 * 6_371_000.0),
                                             abs=1e-6)
    ground_m = math.tan(math.radians(m.camera_gap_deg)) * m.target_depth_m
    assert ground_m == pytest.approx(r_m, abs=1e-3)
    no_fov = Clip(**{**clip.__dict__, "hfov_deg": None})
    assert measures_at(no_fov, 0, d).camera_gap_deg is None


def test_track_camera_gap_is_the_arrows_way_in_camera_pixels(tmp_path: Path) -> None:
    """A tracked arrow r mm from the target: its gap seen from the camera is
    r over the screen's mm per camera pixel, over the focal length."""
    from cosim.trials.measures import arrow_offset_mm, track_measures

    p = write_study(tmp_path, "protocol: track\n" + CLIPS.replace(
        "width_px: 320, height_px: 240,", "width_px: 320, height_px: 240, hfov_deg: 90,"))
    clip = load_study(p).clips[0]
    assert clip.focal_px == pytest.approx(160.0)
    d = participant_display(screen_width_px=1600, screen_height_px=900, screen_width_mm=400,
                            screen_height_mm=225, viewing_distance_mm=500)
    for direction in ((1.0, 0.0), (0.0, -1.0)):
        m = track_measures(clip, d, direction, 2.0, 1500.0)
        r_mm = arrow_offset_mm(2.0, 1500.0, 500.0)
        camera_px = r_mm / (3.75 * 0.25)  # 3.75 screen px a camera px, 0.25 mm a screen px
        assert m.onscreen_distance_mm == pytest.approx(r_mm)
        assert m.camera_gap_deg == pytest.approx(math.degrees(math.atan(camera_px / 160.0)))


def test_a_session_id_never_begins_with_a_dash(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """One random id in 32 began with "-" or "_": a spreadsheet export escaped it as a
    would-be formula, so the exported id no longer matched the stored one."""
    import secrets

    drawn = iter(["-Ce3h3qTpdLT", "_Ce3h3qTpdLT", "Ce3h3qTpdLT0"])
    monkeypatch.setattr(secrets, "token_urlsafe", lambda n: next(drawn))
    with Store(tmp_path / "ids.sqlite") as store:
        s = store.create_session(participant="p01", study="s", protocol="disappear",
                                 display=DISPLAY, order_method="shuffle", seed=7,
                                 session_number=0, trial_order=[{"index": 0}])
    assert s["id"] == "Ce3h3qTpdLT0"
