"""The study file's practice clips, clip fingerprints and files that are not
regular files (the rest of the study file: tests/trials/test_store.py)."""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import threading
from collections.abc import Callable
from pathlib import Path

import pytest
from test_store import CLIPS, _sweep, write_study

from cosim.errors import ConfigError
from cosim.trials.study import load_study

HEAD = "name: s\nprotocol: disappear\npractice: 3\nrepeats: 2\norder: shuffle\nseed: 7\n"
PRACTICE = """\
practice_clips:
  - {video: c2.mp4, ground_truth: c2.gt.csv}
  - {id: warmup, video: c3.mp4, ground_truth: c3.gt.csv, conditions: {speed_kt: 10}}
"""


def test_practice_trials_are_drawn_from_the_practice_clips(tmp_path: Path) -> None:
    p = write_study(tmp_path, HEAD + CLIPS + PRACTICE, clips=4)
    st = load_study(p)
    assert [c.id for c in st.clips] == ["clip0", "clip1"]
    assert [c.id for c in st.practice_clips] == ["practice0", "warmup"]
    assert st.practice_clips[1].condition_map == {"speed_kt": "10"}
    assert [c.id for c in st.all_clips] == ["clip0", "clip1", "practice0", "warmup"]
    (tmp_path / "without").mkdir()
    plain = load_study(write_study(tmp_path / "without", HEAD + CLIPS))
    for session in range(4):
        trials = st.trial_order(session)
        practice = [t for t in trials if t.practice]
        assert len(practice) == 3 and all(t.clip in (2, 3) for t in practice)
        assert [t.index for t in trials] == list(range(len(trials)))
        # the main trials are as without practice clips; their practice, from the clips
        before = plain.trial_order(session)
        assert [(t.clip, t.break_before) for t in trials if not t.practice] == [
            (t.clip, t.break_before) for t in before if not t.practice]
        assert all(t.clip in (0, 1) for t in before if t.practice)
    assert {t.clip for s in range(8) for t in st.trial_order(s) if t.practice} == {2, 3}
    assert st.trial_order(1) == st.trial_order(1)  # the seed decides


def test_practice_clips_from_a_sweep_folder(tmp_path: Path) -> None:
    _sweep(tmp_path / "training", "run_0000/cameras/uav_nadir.mp4")
    p = write_study(tmp_path, "protocol: disappear\npractice: 1\n" + CLIPS +
                    "practice_clips: {folder: training, where: {speed_kt: 50}}\n")
    st = load_study(p)
    (c,) = st.practice_clips
    assert (c.id, c.target) == ("run_0000/uav_nadir", "fire_truck")
    assert (tmp_path / "training").resolve() in st.roots
    assert [t.clip for t in st.trial_order(0) if t.practice] == [2]


@pytest.mark.parametrize("body, match", [
    (HEAD + CLIPS + "practice_clips:\n  - {id: clip1, video: c2.mp4, ground_truth: c2.gt.csv}\n",
     r"study\.yaml:\d+: practice_clips: clip ids also among the main clips: clip1; a practice "
     r"clip needs an id of its own"),
    (HEAD.replace("practice: 3", "practice: 0") + CLIPS + PRACTICE,
     r"study\.yaml:\d+: practice_clips: practice clips given, but `practice:` is 0"),
    (HEAD + CLIPS + "practice_clips:\n  - {video: c9.mp4, ground_truth: c2.gt.csv}\n",
     r"study\.yaml:\d+: practice_clips\[0\]\.video: 'c9\.mp4': the video must be an existing "
     r"file inside the study's folders"),
    (HEAD + CLIPS + "practice_clips: nowhere\n",
     r"study\.yaml:\d+: practice_clips: 'nowhere': cannot open the sweep folder"),
    (HEAD + CLIPS + "practice_clips: []\n",
     r"study\.yaml:\d+: practice_clips: expected a non-empty list of clips"),
])
def test_practice_clip_errors(tmp_path: Path, body: str, match: str) -> None:
    p = write_study(tmp_path, body, clips=4)
    with pytest.raises(ConfigError, match=match):
        load_study(p)


def test_a_clips_fingerprint_is_its_ground_truth_and_video_size(tmp_path: Path) -> None:
    p = write_study(tmp_path, "protocol: disappear\n" + CLIPS)
    c = load_study(p).clips[1]
    assert c.fingerprint == {
        "ground_truth_sha256": hashlib.sha256((tmp_path / "c1.gt.csv").read_bytes()).hexdigest(),
        "video_bytes": (tmp_path / "c1.mp4").stat().st_size}


def _fifo(p: Path) -> Path:
    p.unlink(missing_ok=True)
    os.mkfifo(p)
    return p


def _raised_within(fn: Callable[[], object], fifos: list[Path], timeout_s: float = 10.0
                   ) -> BaseException | None:
    """What ``fn()`` raised, run in a thread. If it is still running after
    ``timeout_s`` (waiting on a FIFO), each FIFO is opened for writing and
    closed, which lets the reader go on, and the test fails."""
    raised: list[BaseException] = []

    def run() -> None:
        try:
            fn()
        except BaseException as e:  # noqa: BLE001 - handed to the test
            raised.append(e)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(timeout_s)
    if th.is_alive():
        for f in fifos:
            with contextlib.suppress(OSError):
                os.close(os.open(f, os.O_WRONLY | os.O_NONBLOCK))
        th.join(10)
        pytest.fail(f"still waiting on a FIFO after {timeout_s} s")
    return raised[0] if raised else None


@pytest.mark.parametrize("fifo, match", [
    ("study.yaml", r"study\.yaml: cannot read the study file: not a regular file"),
    ("c1.mp4", r"study\.yaml:\d+: clips\[1\]\.video: 'c1\.mp4': the video must be an existing "
               r"file inside the study's folders \(.*\); it is a FIFO, not a regular file"),
    ("c1.gt.csv", r"study\.yaml:\d+: clips\[1\]\.ground_truth: 'c1\.gt\.csv': .*; it is a "
                  r"FIFO, not a regular file"),
    ("exp2/manifest.csv", r"study\.yaml:\d+: sweep: .*manifest\.csv: cannot read manifest: "
                          r"not a regular file"),
    ("exp2/run_0000/cameras/uav_nadir.mp4",
     r"study\.yaml:\d+: sweep: .*manifest\.csv:2: video 'run_0000/cameras/uav_nadir\.mp4' must "
     r"be an existing file inside the sweep folder; it is a FIFO, not a regular file"),
])
def test_a_fifo_among_the_study_files_is_refused_not_waited_on(tmp_path: Path, fifo: str,
                                                               match: str) -> None:
    if fifo.startswith("exp2/"):
        _sweep(tmp_path / "exp2", "run_0000/cameras/uav_nadir.mp4")
        p = tmp_path / "study.yaml"
        p.write_text("protocol: disappear\nsweep: exp2\n")
    else:
        p = write_study(tmp_path, "protocol: disappear\n" + CLIPS)
    f = _fifo(tmp_path / fifo)
    e = _raised_within(lambda: load_study(p), [f])
    assert isinstance(e, ConfigError), e
    assert re.search(match, str(e)), str(e)


def test_a_video_made_a_fifo_after_its_check_is_refused_not_waited_on(tmp_path: Path) -> None:
    """The video's probe checks the file it opened: a FIFO put in place of a
    video after the study's path check is refused, not waited on."""
    from cosim.trials.clips import probe_video

    f = _fifo(tmp_path / "v.mp4")
    e = _raised_within(lambda: probe_video(f), [f])
    assert isinstance(e, ConfigError), e
    assert str(e) == f"{f}: it is a FIFO, not a regular file"
