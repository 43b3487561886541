"""The study file's practice clips and clip fingerprints (the rest of the
study file: tests/trials/test_store.py)."""

from __future__ import annotations

import hashlib
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
