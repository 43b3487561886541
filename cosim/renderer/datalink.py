"""A camera's downlink: what its operator sees, as encoded and delivered.

A camera with a ``datalink:`` mapping (``DatalinkSpec``) has its video
encoded as a radio link would carry it: H.264 (x264, ``ultrafast``, tuned
for zero latency: no B-frames, no look-ahead) at a constant bit rate
(``bitrate_kbps``, HRD-conformant CBR with a one-second buffer), every
``every``-th rendered frame (``rate_hz``), a key frame every ``gop``
delivered frames. ``Downlink`` writes the encoded packets as the camera's
video file and decodes them back (below), so the ground truth can be
measured on the frame as delivered (``truth.delivered``); the rendered frame
is not kept. Each delivered frame arrives ``latency_ms`` after it was
rendered (``delivered_time_s`` of the ground truth).

Decoding waits until a delivered frame is looked at (``latest``: a target in
view to measure, an operator view or ``--video`` tap to feed): the packets
since the last decoded one, or since the last key frame, are decoded then, in
order, so each frame decodes exactly as a receiver decoding every packet would
have it, and a stretch of frames with nothing to measure and nobody watching
costs no decoding.

Owns the ``datalink:`` keys and the encoder and decoder; the files are
``outputs``'.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import cv2
import numpy as np

from cosim.core.camera import DatalinkSpec
from cosim.core.section import SectionContext
from cosim.errors import CosimError

P = tuple[Any, ...]

#: the ``datalink:`` limits: bit rate (10 kbit/s to 100 Mbit/s), latency, key-frame interval
MIN_KBPS, MAX_KBPS = 10.0, 100_000.0
MAX_LATENCY_MS = 10_000.0
MIN_KEYFRAME_S, MAX_KEYFRAME_S = 0.0, 60.0
DATALINK_CODECS = ("h264",)
#: the encoder's buffer (HRD/VBV) in seconds of the bit rate
BUFFER_S = 1.0
#: the ground-truth columns a downlink adds after ``truth.GT_COLUMNS``
DELIVERED_COLUMNS = ("delivered_time_s", "delivered_pixels_on_target", "delivered_contrast")


def parse_datalink(info: SectionContext, d: Any, p: P, camera_rate_hz: float | None,
                   size_px: tuple[int | None, int | None] = (None, None)
                   ) -> DatalinkSpec | None:
    """A camera's ``datalink:`` (every key optional); None if a problem was
    reported. ``camera_rate_hz``, ``size_px``: the camera's frame rate and
    (width, height) (None: not known, its problem reported already)."""
    r = info.reader(d, p, ("codec", "bitrate_kbps", "rate_hz", "keyframe_s", "latency_ms"))
    codec = r.string("codec", "h264", choices=DATALINK_CODECS)
    from cosim.renderer.video import have_pyav

    if not have_pyav():
        info.err(p, "a datalink needs PyAV (pip install av) for its H.264 encoder")
    if any(n is not None and n % 2 for n in size_px):
        info.err(p, f"a datalink's H.264 (4:2:0) needs an even frame size; the camera's is "
                    f"{size_px[0]}x{size_px[1]}")
    kbps = r.num("bitrate_kbps", 1000.0, lo=MIN_KBPS, hi=MAX_KBPS)
    latency = r.num("latency_ms", 0.0, lo=0.0, hi=MAX_LATENCY_MS)
    keyframe = r.num("keyframe_s", 1.0, lo=MIN_KEYFRAME_S, hi=MAX_KEYFRAME_S)
    rate = r.num("rate_hz", camera_rate_hz, lo=1e-3, hi=camera_rate_hz)
    if None in (codec, kbps, latency, keyframe, rate) or camera_rate_hz is None:
        return None
    assert rate is not None and keyframe is not None
    every = camera_rate_hz / rate
    if abs(every - round(every)) > 1e-9:
        info.err(p + ("rate_hz",), f"{rate:g} must divide the camera's rate_hz "
                                   f"{camera_rate_hz:g} (a whole number of rendered frames "
                                   f"per delivered one)")
        return None
    return DatalinkSpec(codec=str(codec), bitrate_kbps=float(kbps or 0), rate_hz=rate,
                        every=round(every), gop=max(1, round(keyframe * rate)),
                        latency_ms=float(latency or 0))


class Downlink:
    """One camera's encoded video, written to ``path`` and decoded back:
    ``send(frame)`` encodes a rendered frame (BGRA uint8), ``latest()`` is the
    last one sent as the far end decodes it (BGRA). ``close()`` finishes the
    file."""

    def __init__(self, path: str, spec: DatalinkSpec, width_px: int, height_px: int) -> None:
        import av

        if width_px % 2 or height_px % 2:
            raise CosimError(f"{path}: a datalink's {spec.codec} needs an even frame size, got "
                             f"{width_px}x{height_px}")
        self.spec = spec
        kbps = spec.bitrate_kbps
        rate = Fraction(spec.rate_hz).limit_denominator(1001)
        self.container: Any = av.open(path, "w")
        self.stream = self.container.add_stream("libx264", rate=rate, options={
            "preset": "ultrafast", "tune": "zerolatency", "x264-params": "nal-hrd=cbr",
            "maxrate": f"{kbps:.3f}k", "bufsize": f"{kbps * BUFFER_S:.3f}k",
            "g": str(spec.gop), "keyint_min": str(spec.gop), "sc_threshold": "0",
            "bf": "0"})
        self.stream.width, self.stream.height = width_px, height_px
        self.stream.pix_fmt = "yuv420p"
        self.stream.codec_context.bit_rate = round(kbps * 1000)
        self.stream.codec_context.thread_count = 1
        self.decoder: Any = av.CodecContext.create("h264", "r")
        self.decoder.thread_count = 1
        self.time_base = 1 / rate
        self.yuv = np.empty((height_px * 3 // 2, width_px), np.uint8)
        self.got = np.zeros((height_px, width_px, 4), np.uint8)  # black until a delivery
        self.n = 0
        self.bytes = 0
        #: the packets sent and not yet decoded (from the last key frame at most)
        self.pending: list[bytes] = []

    def send(self, img: np.ndarray) -> None:
        """Encode ``img`` (BGRA) into the file; its decoding waits for ``latest``."""
        cv2.cvtColor(img, cv2.COLOR_BGRA2YUV_I420, dst=self.yuv)
        f = self.picture()
        f.pts, f.time_base = self.n, self.time_base
        self.n += 1
        packets = self.stream.encode(f)
        if len(packets) != 1:  # zero-latency x264: one frame in, one packet out
            raise CosimError(f"the datalink's encoder gave {len(packets)} packets for frame "
                             f"{self.n - 1}, expected 1")
        packet = packets[0]
        self.bytes += packet.size
        if packet.is_keyframe:  # what came before it is never needed again
            self.pending.clear()
        self.pending.append(bytes(packet))  # muxing takes the packet's data
        self.container.mux(packet)

    def picture(self) -> Any:
        """The frame to encode (an av.VideoFrame) over the converted buffer itself,
        not a copy: x264 copies its input picture before encode returns, so the
        next frame may overwrite the buffer."""
        import av

        return av.VideoFrame.from_numpy_buffer(self.yuv, format="yuv420p")

    def latest(self) -> np.ndarray:
        """The last frame sent as the far end decodes it (BGRA, black before
        any; a buffer the next decode reuses)."""
        if not self.pending:
            return self.got
        import av

        if self.decoder.extradata is None:  # mp4's out-of-band parameter sets
            self.decoder.extradata = self.stream.codec_context.extradata
        decoded = []
        for data in self.pending:
            decoded.extend(self.decoder.decode(av.Packet(data)))
        if len(decoded) != len(self.pending):  # FFmpeg's decoder: one in, one out
            raise CosimError(f"the datalink's decoder gave {len(decoded)} frames for "
                             f"{len(self.pending)} packets up to frame {self.n - 1}")
        self.pending.clear()
        cv2.cvtColor(decoded[-1].to_ndarray(format="yuv420p"), cv2.COLOR_YUV2BGRA_I420,
                     dst=self.got)
        return self.got

    def close(self) -> dict[str, Any]:
        """Finish the file; the link's settings, the frames sent and the mean
        bit rate they took (for the stream's entry in summary.json)."""
        if self.container is not None:
            self.container.mux(self.stream.encode(None))
            self.container.close()
            self.container = None
        secs = self.n * float(self.time_base)
        sp = self.spec
        return {"datalink": {"codec": sp.codec, "bitrate_kbps": sp.bitrate_kbps,
                             "rate_hz": sp.rate_hz, "keyframe_every": sp.gop,
                             "latency_ms": sp.latency_ms},
                "delivered_frames": self.n,
                "delivered_kbps": round(self.bytes * 8 / secs / 1000, 1) if secs else None}
