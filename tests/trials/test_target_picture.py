"""Which still the participant page shows of a target, and where it is cut
(the picture itself, from a live server: tests/trials/test_server.py)."""

from __future__ import annotations

from pathlib import Path

from cosim.trials.clips import GtFrame
from cosim.trials.study import Clip
from cosim.trials.target_picture import choose_still


def clip(cid: str, boxes: list[tuple[float, float, float, float] | None],
         target: str = "truck") -> Clip:
    """A 320 x 240 clip whose frames have ``boxes`` (None: not in view)."""
    frames = tuple(GtFrame(k, k / 10, b is not None, b,
                           None if b is None else ((b[0] + b[2]) / 2, (b[1] + b[3]) / 2))
                   for k, b in enumerate(boxes))
    return Clip(id=cid, video=Path(f"{cid}.mp4"), ground_truth=Path(f"{cid}.gt.csv"),
                target=target, run="", rate_hz=10.0, width_px=320, height_px=240,
                conditions=(), frames=frames)


def test_the_largest_box_wholly_in_view_and_the_square_around_it() -> None:
    a = clip("a", [None, (100, 100, 110, 105), (100, 100, 130, 110), (300, 100, 340, 140)])
    b = clip("b", [(10, 10, 20, 20)], target="car")
    s = choose_still((a, b), (), "truck")
    assert s is not None
    # frame 3's box is larger but cut by the edge: frame 2, a square of 60 px
    assert (s.clip.id, s.frame, s.side_px, s.x0, s.y0) == ("a", 2, 60, 85, 75)
    assert choose_still((a,), (), "car") is None


def test_practice_clips_are_preferred_and_a_box_cut_by_the_edge_taken_if_no_other() -> None:
    main = clip("main", [(100, 100, 180, 150)])
    practice = clip("practice", [None, (-20.0, 0.0, 20.0, 30.0)])
    s = choose_still((main,), (practice,), "truck")
    assert s is not None
    # the only practice frame in view, at the corner: the square kept inside the picture
    assert (s.clip.id, s.frame, s.side_px, s.x0, s.y0) == ("practice", 1, 80, 0, 0)
    s = choose_still((main,), (clip("other", [(0, 0, 9, 9)], target="car"),), "truck")
    assert s is not None and s.clip.id == "main"


def test_a_target_never_in_view_has_no_picture() -> None:
    assert choose_still((clip("a", [None, None]),), (), "truck") is None
