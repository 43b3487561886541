"""Lockstep with an outside controller (``MavlinkConfig.lockstep_sysid``),
so that a controller in another process gives the same results as one in
process:

- after the telemetry of every exchange at tick T, vehicle 1 sends TIMESYNC
  ``tc1=0, ts1=T's simulation time in ns`` (an ordinary time-sync request,
  ``request``);
- the controller reads the telemetry, sends its commands, then answers the
  request as the TIMESYNC protocol says (``tc1`` its clock, non-zero;
  ``ts1`` echoed);
- the next exchange first waits (at most ``lockstep_timeout_s``, else
  ``LockstepTimeout``) for that answer from the controller's system id
  (``wait``), then handles everything received: the commands take effect at
  the same tick as an in-process controller's injected ones. The first
  exchange waits for any message from the controller (it says hello with a
  HEARTBEAT).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from cosim.mavlink.errors import LockstepTimeout
from cosim.mavlink.inbox import Received
from cosim.mavlink.link import NullLink, UdpLink
from cosim.mavlink.vehicle import SimClock


class Lockstep:
    """The endpoint's side of the lockstep (see the module docstring)."""

    def __init__(self, clock: SimClock) -> None:
        self.clock = clock
        #: the tick whose answer is awaited (None: the first exchange's hello)
        self.pending: int | None = None

    def request(self, tick: int) -> dict[str, int]:
        """The fields of the TIMESYNC request sent after the telemetry at ``tick``."""
        self.pending = tick
        return {"tc1": 0, "ts1": self.clock.sim_us(tick) * 1000}

    def wait(self, got: Received, poll: Callable[[], Received], link: UdpLink | NullLink,
             tick: int, sysid: int, timeout_s: float) -> Received:
        """``got`` and what ``poll`` receives until the controller (system
        ``sysid``) has answered, within ``timeout_s``; LockstepTimeout naming
        what did not come."""
        pending = self.pending
        ts1 = None if pending is None else self.clock.sim_us(pending) * 1000

        def answered(batch: Received) -> bool:
            for msgs, _ in batch:
                for m in msgs:
                    if m.src_system != sysid:
                        continue
                    if ts1 is None or (m.name == "TIMESYNC" and m.fields["tc1"] != 0
                                       and m.fields["ts1"] == ts1):
                        return True
            return False

        done = answered(got)
        deadline = time.monotonic() + timeout_s
        while not done:
            left = deadline - time.monotonic()
            if left <= 0 or isinstance(link, NullLink):
                what = "message" if ts1 is None else f"TIMESYNC answer for tick {pending}"
                raise LockstepTimeout(
                    f"mavlink lockstep: no {what} from the controller (system {sysid}) "
                    f"within {timeout_s:g} s at tick {tick}; is it running and talking to "
                    f"{link.url}?")
            if link.wait_readable(min(left, 0.5)):
                batch = poll()
                got.extend(batch)
                done = answered(batch)
        self.pending = None
        return got
