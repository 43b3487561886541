"""What arrives from the network for an endpoint: every datagram waiting
(at most ``MavlinkConfig.max_datagrams_per_exchange``), decoded, each with
its sender.

With MAVLink 2 signing on (``cosim.mavlink.signing``), a received packet is
handled only if it carries a valid signature made with the run's key and a
timestamp newer than the last accepted one of its stream (link id, system,
component) or, for a stream not seen before, not more than a minute behind
the newest timestamp known; otherwise it is dropped before anything looks
at it and counted (``admit``). A correctly signed packet on one of our
vehicles' streams is our own packet sent back (``echoes``); SETUP_SIGNING
is never obeyed, even correctly signed: the key comes from the operator
only. Messages an in-process client injects are not checked.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

from cosim.mavlink import adapter as mav
from cosim.mavlink.link import NullLink, UdpLink
from cosim.mavlink.signing import SharedSigning

#: one poll's datagrams: the messages of each, with its sender
Received = list[tuple[list[mav.Message], tuple[str, int]]]

#: the counter of each verdict that drops a packet (``SIG_MAVLINK1`` counts
#: in ``unsigned_dropped`` too; any other verdict is a replay)
_DROPPED = {mav.SIG_MAVLINK1: ("mavlink1_dropped", "unsigned_dropped"),
            mav.SIG_UNSIGNED: ("unsigned_dropped",),
            mav.SIG_BAD: ("bad_signature_dropped",),
            mav.SIG_STALE: ("stale_stream_dropped",),
            mav.SIG_OWN: ("echoes",)}


class Inbox:
    """The receiving side of one endpoint's ``link``; ``signing``: the key's
    replay protection (None: signing off, nothing is checked)."""

    def __init__(self, link: UdpLink | NullLink, counts: Counter[str],
                 signing: SharedSigning | None) -> None:
        self.link = link
        self.counts = counts
        self.signing = signing
        self.decoder = mav.Decoder()

    def poll(self) -> Received:
        """The datagrams waiting now, decoded and, with signing, authenticated
        (all at once: one look at the shared signing state)."""
        got = [(self.decoder.decode(data), addr) for data, addr in self.link.poll()]
        if self.signing is None:
            return got
        verdicts = iter(self.signing.authenticate([m.raw for msgs, _ in got for m in msgs]))
        return [([a for a in (admit(m, next(verdicts), self.counts) for m in msgs)
                  if a is not None], addr) for msgs, addr in got]


def admit(m: mav.Message, verdict: str, counts: Counter[str]) -> mav.Message | None:
    """A received message if ``verdict`` (its signature's) is good (marked
    signed), else None, counted; SETUP_SIGNING is never obeyed."""
    if verdict != mav.SIG_OK:
        for name in _DROPPED.get(verdict, ("replay_dropped",)):
            counts[name] += 1
        return None
    if m.name == "SETUP_SIGNING":
        # the key comes from the operator's file or variable, never the network
        counts["setup_signing_ignored"] += 1
        return None
    return replace(m, signed=True)
