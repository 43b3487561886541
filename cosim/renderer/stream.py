"""Camera video to a ground station: ``cosim run --video SYSID[:CAM]=udp://HOST:PORT``.

The frames the cameras render anyway (``RunContext.frame_taps``, at the
camera's full size) are encoded as H.264 (libx264, ultrafast, zero latency,
a key frame every second) and sent over UDP by FFmpeg's own muxers through
PyAV: RTP by default (what QGroundControl's "UDP h.264 Video Stream" plays;
an SDP file for ``ffplay`` is written into the run folder), or MPEG-TS with
``udp://HOST:PORT?format=mpegts``. Encoding runs on a thread of its own with
a short queue: if it falls behind, frames are dropped (counted) rather than
the simulation waiting. The simulation never sees the stream.

Destinations are loopback addresses unless ``allow_remote`` (``cosim run
--video-allow-remote``): a camera feed is not sent off the machine by
accident. IPv6 addresses are written in brackets (``udp://[::1]:5600``).
Each stream's VIDEO_STREAM_INFORMATION (``info``) is what the vehicle
answers on MAVLink.

A stream that fails (FFmpeg cannot send to its destination), or sends no
frame in a run that completes, fails the run at its end (``VideoStreamError``
naming the stream; ``cosim run`` exits 1), after the simulation went on: the
user asked for video and got none.
"""

from __future__ import annotations

import logging
import queue
import re
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np

from cosim.core.netaddr import is_loopback
from cosim.errors import ConfigError, CosimError
from cosim.sync.participants import ParticipantFailed

log = logging.getLogger(__name__)

FORMATS = ("rtp", "mpegts")
#: frames waiting to be encoded before new ones are dropped
QUEUE_FRAMES = 8
_SPEC = re.compile(r"^(?P<sysid>\d+)(?::(?P<cam>[A-Za-z0-9_.-]+))?=(?P<url>.+)$")


class VideoStreamError(CosimError):
    """A requested video stream failed or sent nothing."""


@dataclass(frozen=True)
class VideoTarget:
    """One ``--video`` option: which camera goes where, how."""

    sysid: int
    camera: str | None  # None: the vehicle's first camera
    host: str
    port: int
    fmt: str  # "rtp" or "mpegts"

    @property
    def ipv6(self) -> bool:
        return ":" in self.host

    @property
    def netloc(self) -> str:
        """``HOST:PORT`` as a URL writes it (an IPv6 address in brackets)."""
        return f"[{self.host}]:{self.port}" if self.ipv6 else f"{self.host}:{self.port}"

    @property
    def uri(self) -> str:
        return f"udp://{self.netloc}"


def parse_target(text: str, allow_remote: bool = False) -> VideoTarget:
    """``SYSID[:CAM]=udp://HOST:PORT[?format=rtp|mpegts]``; ConfigError saying
    what is wrong."""
    m = _SPEC.match(text.strip())
    if m is None:
        raise ConfigError(f"--video {text!r}: expected SYSID[:CAMERA]=udp://HOST:PORT, e.g. "
                          f"1=udp://127.0.0.1:5600")
    sysid = int(m["sysid"])
    if not 1 <= sysid <= 250:
        raise ConfigError(f"--video {text!r}: system id must be 1..250, got {sysid}")
    u = urlsplit(m["url"])
    if u.scheme != "udp" or not u.hostname or u.port is None:
        raise ConfigError(f"--video {text!r}: expected udp://HOST:PORT, got {m['url']!r}")
    fmt = parse_qs(u.query).get("format", ["rtp"])[0]
    if fmt not in FORMATS:
        raise ConfigError(f"--video {text!r}: format must be one of {', '.join(FORMATS)}, "
                          f"got {fmt!r}")
    if not 1 <= u.port <= 65535:
        raise ConfigError(f"--video {text!r}: port must be 1..65535")
    host = u.hostname
    if not allow_remote and not is_loopback(host):
        raise ConfigError(f"--video {text!r}: {host} is not a loopback address; pass "
                          f"--video-allow-remote to send camera video off this machine")
    return VideoTarget(sysid, m["cam"], host, u.port, fmt)


def sdp(target: VideoTarget, name: str) -> str:
    """The SDP describing an RTP H.264 stream (what ffplay opens)."""
    ip = "IP6" if target.ipv6 else "IP4"
    return (f"v=0\no=- 0 0 IN {ip} {target.host}\ns={name}\nc=IN {ip} {target.host}\nt=0 0\n"
            f"m=video {target.port} RTP/AVP 96\na=rtpmap:96 H264/90000\n"
            f"a=fmtp:96 packetization-mode=1\n")


class _Encoder:
    """One camera's H.264 stream, encoded and sent on its own thread."""

    def __init__(self, target: VideoTarget, width: int, height: int, rate_hz: float) -> None:
        import av

        self.target = target
        self.width, self.height = width - width % 2, height - height % 2
        url = (f"rtp://{target.netloc}" if target.fmt == "rtp"
               else f"udp://{target.netloc}?pkt_size=1316")
        self.container = av.open(url, mode="w", format=target.fmt)
        fps = max(1, round(rate_hz))
        s = self.container.add_stream("libx264", rate=fps)
        s.width, s.height, s.pix_fmt = self.width, self.height, "yuv420p"
        s.options = {"preset": "ultrafast", "tune": "zerolatency", "g": str(fps),
                     "bf": "0"}
        self.stream = s
        self.queue: queue.Queue[tuple[int, np.ndarray] | None] = queue.Queue(QUEUE_FRAMES)
        self.sent = self.dropped = 0
        self.error: str | None = None
        self.thread = threading.Thread(target=self._run, name=f"video-{target.port}",
                                       daemon=True)
        self.thread.start()

    def put(self, index: int, bgr: np.ndarray) -> None:
        try:
            self.queue.put_nowait((index, bgr))
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        import av

        try:
            while True:
                job = self.queue.get()
                if job is None:
                    break
                index, bgr = job
                if bgr.shape[:2] != (self.height, self.width):  # an operator view's tile
                    import cv2

                    bgr = cv2.resize(bgr, (self.width, self.height))
                frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(bgr), format="bgr24")
                frame.pts = index
                for packet in self.stream.encode(frame):
                    self.container.mux(packet)
                self.sent += 1
            for packet in self.stream.encode(None):
                self.container.mux(packet)
        except Exception as e:  # a send that fails ends this stream, never the run
            self.error = f"{type(e).__name__}: {e}"
            log.warning("video to %s stopped: %s", self.target.uri, self.error)
        finally:
            try:
                self.container.close()
            except Exception:  # noqa: BLE001 (closing a broken stream)
                pass

    def close(self) -> dict[str, Any]:
        try:
            self.queue.put(None, timeout=5.0)
        except queue.Full:
            pass
        self.thread.join(10.0)
        return {"uri": self.target.uri, "format": self.target.fmt, "frames_sent": self.sent,
                "frames_dropped": self.dropped, **({"error": self.error} if self.error else {})}


class VideoParticipant:
    """Streams the ``--video`` cameras (see the module docstring)."""

    name = "video"

    def __init__(self, targets: Sequence[VideoTarget], scenario: Any) -> None:
        """Which camera each target streams (ConfigError: no such vehicle or camera)."""
        self.targets = list(targets)
        self.encoders: dict[tuple[str, str], _Encoder] = {}
        self.by_stream: dict[tuple[str, str], VideoTarget] = {}
        self.cams: dict[tuple[str, str], Any] = {}
        self.info: dict[int, list[dict[str, Any]]] = {}
        scn = scenario
        cams = scn.sections.get("cameras")
        views = list(cams.views) if cams is not None else []
        for t in self.targets:
            row = t.sysid - 1
            if row >= len(scn.vehicles):
                raise ConfigError(f"--video {t.sysid}: no vehicle has system id {t.sysid} "
                                  f"(this run has 1..{len(scn.vehicles)})")
            vid = scn.vehicles[row].id
            mine = [c for c in views if row in c.vehicles]
            if not mine:
                raise ConfigError(f"--video {t.sysid}: vehicle {vid} has no camera")
            cam = next((c for c in mine if c.name == t.camera), None) if t.camera else mine[0]
            if cam is None:
                raise ConfigError(f"--video {t.sysid}:{t.camera}: vehicle {vid} has no camera "
                                  f"{t.camera!r}; it has {', '.join(c.name for c in mine)}")
            if (vid, cam.name) in self.by_stream:
                raise ConfigError(f"--video {t.sysid}:{cam.name}: given twice")
            self.by_stream[(vid, cam.name)] = t
            self.cams[(vid, cam.name)] = cam
            self.info.setdefault(t.sysid, []).append(self._info(t, cam, vid))

    def prepare(self, ctx: Any) -> None:
        """Before any participant starts: the cameras' frames, at full size."""
        ctx.frame_taps.append((self.frame, None))

    @staticmethod
    def _info(t: VideoTarget, cam: Any, vehicle: str) -> dict[str, Any]:
        """VIDEO_STREAM_INFORMATION fields (stream ids set by the endpoint)."""
        from cosim.mavlink import adapter as mav

        return {"type": mav.VIDEO_STREAM_TYPE_RTPUDP if t.fmt == "rtp"
                else mav.VIDEO_STREAM_TYPE_MPEG_TS,
                "flags": mav.VIDEO_STREAM_STATUS_FLAGS_RUNNING,
                "framerate": float(cam.rate_hz), "resolution_h": int(cam.width_px),
                "resolution_v": int(cam.height_px), "bitrate": 0, "rotation": 0,
                "hfov": round(float(cam.hfov_deg)), "name": f"{vehicle}/{cam.name}"[:31],
                "uri": t.uri, "encoding": mav.VIDEO_STREAM_ENCODING_H264}

    def start(self, ctx: Any) -> None:
        self.ctx = ctx
        for key, t in self.by_stream.items():
            cam = self.cams[key]
            if t.fmt == "rtp":
                (ctx.out_dir / f"video_{t.sysid}_{cam.name}.sdp").write_text(
                    sdp(t, f"cosim {key[0]}/{key[1]}"))
            self.encoders[key] = _Encoder(t, cam.width_px, cam.height_px, cam.rate_hz)
            log.info("video: %s/%s as H.264 over %s to %s", key[0], key[1], t.fmt.upper(),
                     t.uri)
        if ctx.mavlink is not None:
            ctx.mavlink.set_video(self.info)

    def frame(self, vehicle: str, camera: str, time_s: float, bgr: np.ndarray) -> None:
        enc = self.encoders.get((vehicle, camera))
        if enc is not None:
            cam = self.cams[(vehicle, camera)]
            enc.put(round(time_s * cam.rate_hz), bgr)

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        return None

    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        """Each stream's counts; ``ParticipantFailed`` (``VideoStreamError``)
        naming the streams that failed, or sent no frame in a completed run."""
        section = {f"{v}/{c}": e.close() for (v, c), e in self.encoders.items()}
        failed = []
        for name, st in section.items():
            what = f"video {name} to {st['uri']}"
            if "error" in st:
                failed.append(f"{what} stopped after {st['frames_sent']} frame(s): "
                              f"{st['error']}")
            elif st["frames_sent"] == 0 and reason == "completed":
                failed.append(f"{what} sent no frame ({st['frames_dropped']} dropped)")
        if failed:
            raise ParticipantFailed(VideoStreamError("; ".join(failed)), section)
        return section

    def after_run(self, out_dir: Path) -> None:
        return None
