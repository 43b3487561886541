"""Pausing a run (``Run.pause``/``resume``): the loop waits before its next
exchange, simulated time stops, nothing is skipped; the pacer's clock stops
with it."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from cosim.logs import read_states
from cosim.scenario import load_scenario
from cosim.sync import Run
from cosim.sync.pacing import Pacer
from tests.helpers import same_states


class PauseAt:
    """A participant that pauses its run at the first exchange at or after
    ``tick`` and has it resumed ``hold_s`` later from another thread."""

    name = "pause_at"

    def __init__(self, tick: int, hold_s: float | None) -> None:
        self.tick, self.hold_s = tick, hold_s
        self.run: Run | None = None
        self.paused_at: int | None = None
        self.ticks: list[int] = []

    def start(self, ctx: Any) -> None:
        pass

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        self.ticks.append(tick)
        if self.paused_at is None and tick >= self.tick:
            assert self.run is not None
            self.paused_at = tick
            self.run.pause()
            if self.hold_s is not None:
                threading.Timer(self.hold_s, self.run.resume).start()

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        return None

    def after_run(self, out_dir: Path) -> None:
        return None


def _run(scn: Any, out: Path, part: PauseAt | None, **kw: Any) -> Any:
    run = Run(scn, out, backend="inline", extra_participants=[part] if part else [], **kw)
    if part is not None:
        part.run = run
    return run, run.run()


def test_a_paused_run_gives_the_states_of_one_never_paused(mixed_scenario: Path,
                                                          tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    _, plain = _run(scn, tmp_path / "plain", None)
    part = PauseAt(361, hold_s=0.4)
    run, held = _run(scn, tmp_path / "held", part)
    assert plain.ok and held.ok, held.summary
    assert part.paused_at == 364 and not run.paused  # the first exchange at or after 361
    assert same_states(read_states(plain.out_dir), read_states(held.out_dir))
    assert part.ticks == list(range(0, 720, 4))  # every exchange, none skipped
    # held from the end of the exchange that asked (its timer already running)
    # to the resume 0.4 s after the ask: 0.4 s less what was left of that exchange
    assert held.summary["paused_s"] >= 0.2 and "paused_s" not in plain.summary
    # the pause is not the loop's time
    assert held.summary["wall_time_s"] < held.summary["paused_s"] + plain.summary[
        "wall_time_s"] * 3


def test_a_stop_ends_a_paused_run(mixed_scenario: Path, tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario)
    part = PauseAt(120, hold_s=None)  # never resumed
    run = Run(scn, tmp_path / "out", backend="inline", extra_participants=[part])
    part.run = run
    threading.Timer(0.5, run.stop, args=("stopped while paused",)).start()
    t0 = time.monotonic()
    res = run.run()
    assert res.stop_reason == "stopped while paused" and res.ticks == 124
    assert time.monotonic() - t0 < 30


def test_the_pacer_does_not_count_a_pause_as_lateness() -> None:
    """Held 0.3 s: the next tick is on time (sleeps to its deadline), not
    0.3 s late, and the run does not race to catch up afterwards."""
    p = Pacer(1.0)
    p.start()
    p.pace(0.0)
    p.hold()
    time.sleep(0.3)
    p.release()
    late = p.pace(0.02)
    assert late < 0.1, late
    assert p.stats()["lateness_ms_max"] < 100
    q = Pacer(1.0)  # the same without hold: the pause is lateness
    q.start()
    q.pace(0.0)
    time.sleep(0.3)
    assert q.pace(0.02) > 0.2


def test_a_paced_run_paused_keeps_real_time_after_the_pause(mixed_scenario: Path,
                                                            tmp_path: Path) -> None:
    scn = load_scenario(mixed_scenario).with_duration(2.0)
    part = PauseAt(120, hold_s=0.8)
    _, res = _run(scn, tmp_path / "rt", part, realtime=1.0)
    assert res.ok
    rt = res.summary["realtime"]
    # not one tick 0.8 s late (the pause), the ticks after it paced, not raced
    assert rt["lateness_ms_max"] < 500, rt
    assert res.summary["paused_s"] >= 0.5  # the timer runs from the pause request
