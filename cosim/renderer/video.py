"""Video files for the cameras and the operator view: one writer per file.

``open_video(path, codec, rate_hz, width_px, height_px)`` returns an object
with ``write(frame)`` (BGR or BGRA uint8; alpha is ignored) and ``release()``.
``mp4v`` (MPEG-4 Part 2 in .mp4) and ``h264`` (H.264 in .mp4, plays in
browsers) are encoded with PyAV (FFmpeg's own encoders, one thread per writer:
a render worker owns one core) from the YUV 4:2:0 planes of
``cv2.cvtColor(..., COLOR_BGR[A]2YUV_I420)``;
OpenCV's ``VideoWriter`` converts the colour itself at about six times the
cost (see benchmarks/README.md). Without PyAV, or for an odd frame size
(OpenCV's writer then drops the last column or row, as before), ``mp4v`` falls back to
OpenCV's writer (same format, ~0.6 ms more a 640x480 frame); ``h264`` needs
PyAV (OpenCV's wheels have no H.264 encoder). ``mjpg`` (Motion JPEG in .avi)
is always OpenCV's.

Quality: ``mp4v`` uses a constant quantiser of 4 (PSNR ~37 dB on the
flyover's ground, about the size OpenCV's writer gives), ``h264`` x264's
``ultrafast`` preset at CRF 23 (its default quality; ~0.4 ms more a frame).
"""

from __future__ import annotations

import importlib.util
from fractions import Fraction
from typing import Any, Protocol

import cv2
import numpy as np

from cosim.errors import CosimError

#: codec -> file extension
EXTENSIONS = {"mp4v": "mp4", "h264": "mp4", "mjpg": "avi"}
MPEG4_QUANTISER = 4
H264_PRESET, H264_CRF = "ultrafast", 23


def have_pyav() -> bool:
    return importlib.util.find_spec("av") is not None


class VideoSink(Protocol):
    def write(self, img: np.ndarray) -> None: ...

    def release(self) -> None: ...


class _PyAvWriter:
    """Frames (BGR uint8, all the same size) -> an .mp4 through PyAV."""

    def __init__(self, path: str, codec: str, rate_hz: float, width_px: int,
                 height_px: int) -> None:
        import av

        if width_px % 2 or height_px % 2:
            raise CosimError(f"{path}: {codec} needs an even frame size, got "
                             f"{width_px}x{height_px}")
        self.w, self.h = width_px, height_px
        rate = Fraction(rate_hz).limit_denominator(1001)
        self.container: Any = av.open(path, "w")
        if codec == "h264":
            stream = self.container.add_stream(
                "libx264", rate=rate, options={"preset": H264_PRESET, "crf": str(H264_CRF)})
        else:
            stream = self.container.add_stream("mpeg4", rate=rate)
            stream.codec_context.qmin = stream.codec_context.qmax = MPEG4_QUANTISER
        stream.width, stream.height, stream.pix_fmt = width_px, height_px, "yuv420p"
        stream.codec_context.thread_count = 1
        self.stream = stream
        self.time_base = 1 / rate
        self.yuv = np.empty((height_px * 3 // 2, width_px), np.uint8)
        self.frame = av.VideoFrame(width_px, height_px, "yuv420p")
        self.n = 0
        # the frame handed to the encoder wraps ``yuv`` itself (no copy into
        # FFmpeg's planes) where this PyAV can; both encoders copy or finish with
        # their input within encode(), which the tests check by reading frames back
        self.wrap = getattr(av.VideoFrame, "from_numpy_buffer", None)

    def write(self, img: np.ndarray) -> None:
        cv2.cvtColor(img, cv2.COLOR_BGRA2YUV_I420 if img.shape[2] == 4 else cv2.COLOR_BGR2YUV_I420,
                     dst=self.yuv)
        f = None
        if self.wrap is not None:
            try:
                f = self.wrap(self.yuv, format="yuv420p")
            except (TypeError, ValueError):
                self.wrap = None
        if f is None:
            f = self.frame
            f.make_writable()  # copies only if the encoder still holds the last frame's buffer
            w, h, y = self.w, self.h, self.yuv.reshape(-1)
            offs = (0, w * h, w * h + w * h // 4, w * h * 3 // 2)
            for k, (pw, ph) in enumerate(((w, h), (w // 2, h // 2), (w // 2, h // 2))):
                plane = f.planes[k]
                dst = np.frombuffer(memoryview(plane), np.uint8).reshape(
                    -1, plane.line_size)[:ph, :pw]
                dst[...] = y[offs[k]:offs[k + 1]].reshape(ph, pw)
        f.pts = self.n
        f.time_base = self.time_base
        self.container.mux(self.stream.encode(f))
        self.n += 1

    def release(self) -> None:
        if self.container is None:
            return
        self.container.mux(self.stream.encode(None))
        self.container.close()
        self.container = None


class _OpenCvWriter:
    def __init__(self, path: str, codec: str, rate_hz: float, width_px: int,
                 height_px: int) -> None:
        fourcc = {"mp4v": "mp4v", "mjpg": "MJPG"}[codec]
        self.video = cv2.VideoWriter(path, cv2.VideoWriter.fourcc(*fourcc), rate_hz,
                                     (width_px, height_px))
        if not self.video.isOpened():
            raise CosimError(f"cannot open a {codec} video writer for {path}")

    def write(self, img: np.ndarray) -> None:
        self.video.write(cv2.cvtColor(img, cv2.COLOR_BGRA2BGR) if img.shape[2] == 4 else img)

    def release(self) -> None:
        self.video.release()


def open_video(path: str, codec: str, rate_hz: float, width_px: int, height_px: int
               ) -> VideoSink:
    """A writer for ``codec`` (see the module docstring); raises CosimError if
    the file cannot be opened or ``h264`` is asked for without PyAV."""
    if codec == "h264" and not have_pyav():
        raise CosimError(f"cannot write {path}: codec h264 needs PyAV (pip install av)")
    odd = bool(width_px % 2 or height_px % 2)  # 4:2:0 needs even sizes: OpenCV crops a pixel
    if codec == "h264" or (codec == "mp4v" and not odd and have_pyav()):
        try:
            return _PyAvWriter(path, codec, rate_hz, width_px, height_px)
        except CosimError:
            raise
        except Exception as e:
            raise CosimError(f"cannot open a {codec} video writer for {path}: {e}") from e
    return _OpenCvWriter(path, codec, rate_hz, width_px, height_px)
