"""Batch encoding against pymavlink: byte for byte, for every message cosim
streams, with random values, zero tails (MAVLink 2 truncation) and every
sequence number and system id range."""

from __future__ import annotations

import time

import numpy as np
import pytest

from cosim.mavlink import adapter as mav
from cosim.mavlink import batch
from cosim.mavlink.batch import BatchEncoder
from cosim.mavlink.link import MAX_DATAGRAM_BYTES, UdpLink
from cosim.mavlink.vehicle import STREAMABLE

_INT_RANGES = {"u1": (0, 255), "i1": (-128, 127), "<u2": (0, 65535), "<i2": (-32768, 32767),
               "<u4": (0, 2 ** 32 - 1), "<i4": (-2 ** 31, 2 ** 31 - 1),
               "<u8": (0, 2 ** 62), "<i8": (-2 ** 62, 2 ** 62)}


def _random_fields(name: str, n: int, rng: np.random.Generator) -> list[dict]:
    _, _, layout = mav.wire_layout(name)
    rows: list[dict] = []
    for _ in range(n):
        zero_tail = rng.random() < 0.4  # exercise payload truncation
        d: dict = {}
        for k, (f, t, size) in enumerate(layout):
            tail = zero_tail and k >= len(layout) // 2

            def one(t: str = t, tail: bool = tail) -> object:
                if t.startswith("S"):
                    return "" if tail else "ab"
                if t in ("<f4", "<f8"):
                    return 0.0 if tail else float(rng.normal(0, 1e3))
                lo, hi = _INT_RANGES[t]
                return 0 if tail else int(rng.integers(lo, hi, endpoint=True))
            d[f] = [one() for _ in range(size)] if size else one()
        rows.append(d)
    return rows


@pytest.mark.parametrize("c_crc", [True, False], ids=["fastcrc", "numpy-crc"])
@pytest.mark.parametrize("name", STREAMABLE)
def test_batch_packets_equal_pymavlink_byte_for_byte(name: str, c_crc: bool,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    if not c_crc:
        monkeypatch.setattr(batch, "_CRC", None)
    elif batch._CRC is None:
        pytest.skip("fastcrc (a pymavlink dependency) is not installed")
    rng = np.random.default_rng(sum(map(ord, name)))
    n = 40
    rows = _random_fields(name, n, rng)
    sysids = rng.integers(1, 251, n)
    seqs = rng.integers(0, 256, n)
    enc = BatchEncoder(name)
    cols = {f: [r[f] for r in rows] for f in rows[0]}
    blob, lens = enc.encode(enc.payloads(n, cols), sysids, seqs)
    assert int(lens.sum()) == len(blob)
    off = 0
    for i in range(n):
        p = mav.Packer(int(sysids[i]))
        p.seq = int(seqs[i])
        ref = p.pack(name, **dict(rows[i]))
        got = blob[off:off + int(lens[i])]
        off += int(lens[i])
        assert got == ref, f"{name} row {i}: {got.hex()} != {ref.hex()}"


def test_packets_share_datagrams_without_being_split() -> None:
    rx = UdpLink("udpin:127.0.0.1:0")
    tx = UdpLink(f"udpout:127.0.0.1:{rx.local_address[1]}")
    try:
        enc = BatchEncoder("GLOBAL_POSITION_INT")
        n = 100
        blob, lens = enc.encode(enc.payloads(n, {"lat": np.arange(1, n + 1)}),
                                np.arange(1, n + 1), np.zeros(n, dtype=int))
        tx.send_packets(blob, lens.tolist())
        got: list[bytes] = []
        deadline = time.monotonic() + 2
        while sum(map(len, got)) < len(blob) and time.monotonic() < deadline:
            got += [d for d, _ in rx.poll()]
        assert b"".join(got) == blob
        assert 1 < len(got) < n and max(map(len, got)) <= MAX_DATAGRAM_BYTES
        dec = mav.Decoder()
        msgs = [m for d in got for m in dec.decode(d)]
        assert [m.fields["lat"] for m in msgs] == list(range(1, n + 1))
        assert dec.counts["truncated"] == 0
    finally:
        tx.close()
        rx.close()
