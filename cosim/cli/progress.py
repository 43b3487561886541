"""Progress of a long run: a bar on a terminal, a log line every few seconds
otherwise."""

from __future__ import annotations

import logging
import time
from typing import TextIO

log = logging.getLogger("cosim")

class Progress:
    """A bar on a terminal; a log line every ``every_s`` seconds otherwise.

    The real-time factor shown is the run's one definition (README, "Running
    scenarios"): simulated seconds over wall seconds of the tick loop, counted
    from the loop's first report (the build and trim are not in it), as
    ``summary.json``'s ``real_time_factor``; the final line of ``cosim run``
    prints the summary's figure, so the last bar shows none."""

    def __init__(self, stream: TextIO, hz: float, every_s: float = 10.0) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.hz = hz
        self.every_s = every_s if not self.tty else 0.1
        self.start: tuple[float, int] | None = None  # (wall, tick) of the first report
        self.last = 0.0

    def __call__(self, tick: int, total: int) -> None:
        now = time.monotonic()
        if self.start is None:
            self.start = (now, tick)
            self.last = now if not self.tty else 0.0
        if now - self.last < self.every_s and tick < total:
            return
        self.last = now
        wall = now - self.start[0]
        sim = tick / self.hz
        rtf = (tick - self.start[1]) / self.hz / wall if wall > 0 else 0.0
        frac = tick / total if total else 1.0
        done = tick >= total
        if self.tty:
            width = 30
            bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
            speed = "" if done else f"  {rtf:6.2f}x real time"
            self.stream.write(f"\r[{bar}] {frac:6.1%}  t={sim:8.1f} s{speed} ")
            if done:
                self.stream.write("\n")
            self.stream.flush()
        elif not done:
            log.info("progress: %.1f%% (sim %.1f s of %.1f s, %.2fx real time)", frac * 100,
                     sim, total / self.hz, rtf)
