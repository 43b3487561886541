"""What the libraries cost per camera frame: the part of a frame we do not write.

    python benchmarks/floor_bench.py [--frames 200] [--rounds 2]

Renders the frames of ``render_bench.py``'s camera (640x480 nadir at 100 m AGL,
51 m/s over the flyover's ground and targets) once, keeps them, then measures on
those same frames, in rounds that alternate the candidates so machine noise hits
them alike (CPU time, one thread, min over the rounds):

1. the encoders PyAV's FFmpeg offers, each from the same YUV 4:2:0 planes: ms a
   frame, file size, and luma PSNR of the decoded frames against their input
   (what each costs in quality); the first is what ``mp4v`` uses;
2. the colour conversion ahead of them (``cv2.COLOR_BGRA2YUV_I420``);
3. OpenCV's warp of a ground patch to a frame: the bilinear BGRA warp the
   renderer does, and the variants that look cheaper (one channel, three
   channels, an affine map, nearest neighbour).

The sum of the encoder, the conversion and the warp is the floor of a frame's
cost with these libraries: ``render_bench.py`` reports the rest (tiles, ground
truth, our Python) next to it.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable
from fractions import Fraction
from typing import Any

import av
import cv2
import numpy as np
import render_bench

from cosim.renderer import outputs
from cosim.renderer import video as video_mod

#: name -> (FFmpeg encoder, its options, codec-context settings, file extension)
ENCODERS: dict[str, tuple[str, dict[str, str], dict[str, int], str]] = {
    "mpeg4 q4 (mp4v, the default)": ("mpeg4", {}, {"qmin": video_mod.MPEG4_QUANTISER,
                                                   "qmax": video_mod.MPEG4_QUANTISER}, "mp4"),
    "mpeg4 q5": ("mpeg4", {}, {"qmin": 5, "qmax": 5}, "mp4"),
    "mpeg4 q4, key frame every 50": ("mpeg4", {"g": "50"}, {"qmin": 4, "qmax": 4}, "mp4"),
    "mpeg4 q4, B-frames (bf 1)": ("mpeg4", {"bf": "1"}, {"qmin": 4, "qmax": 4}, "mp4"),
    "mpeg4 q4, no motion search": ("mpeg4", {"motion_est": "zero"}, {"qmin": 4, "qmax": 4},
                                   "mp4"),
    "libx264 ultrafast crf 23 (h264)": ("libx264", {"preset": video_mod.H264_PRESET,
                                                    "crf": str(video_mod.H264_CRF)}, {}, "mp4"),
    "libx264 ultrafast fastdecode": ("libx264", {"preset": "ultrafast", "tune": "fastdecode",
                                                 "crf": "23"}, {}, "mp4"),
    "libvpx (VP8) realtime, cpu-used 16": ("libvpx", {"deadline": "realtime", "cpu-used": "16",
                                                      "crf": "10", "b": "2M"}, {}, "webm"),
}


def frames_of(n: int) -> list[np.ndarray]:
    """The BGRA frames render_bench's camera makes (the video writer's input)."""
    got: list[np.ndarray] = []

    class Keep:
        def write(self, img: np.ndarray) -> None:
            got.append(img.copy())

        def release(self) -> None:
            pass

    opened = outputs.open_video  # the stream writers' (render_bench times it)
    outputs.open_video = lambda *a: Keep()
    try:
        with tempfile.TemporaryDirectory() as cache:
            render_bench.per_frame(n, cache)
    finally:
        outputs.open_video = opened
    return got


def encode(yuvs: list[np.ndarray], encoder: str, options: dict[str, str],
           context: dict[str, int], path: str) -> float:
    """ms CPU a frame to encode ``yuvs`` into ``path`` (one thread)."""
    h, w = yuvs[0].shape[0] * 2 // 3, yuvs[0].shape[1]
    out = av.open(path, "w")
    stream: Any = out.add_stream(encoder, rate=Fraction(10), options=options)
    stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
    stream.codec_context.thread_count = 1
    for k, v in context.items():
        setattr(stream.codec_context, k, v)
    c = time.process_time()
    for i, yuv in enumerate(yuvs):
        f = av.VideoFrame.from_numpy_buffer(yuv, format="yuv420p")
        f.pts, f.time_base = i, Fraction(1, 10)
        out.mux(stream.encode(f))
    out.mux(stream.encode(None))
    ms = (time.process_time() - c) / len(yuvs) * 1000
    out.close()
    return ms


def psnr_y(path: str, yuvs: list[np.ndarray]) -> tuple[float, int]:
    """Mean luma PSNR (dB) of the decoded frames against ``yuvs``, and their count."""
    h = yuvs[0].shape[0] * 2 // 3
    got = []
    with av.open(path) as f:
        for i, fr in enumerate(f.decode(video=0)):
            d = fr.to_ndarray(format="yuv420p")[:h].astype(np.float64) - yuvs[i][:h]
            got.append(10 * np.log10(255.0**2 / max(float(np.mean(d * d)), 1e-12)))
    return float(np.mean(got)), len(got)


def per_call_ms(fn: Callable[[], Any], n: int) -> float:
    c = time.process_time()
    for _ in range(n):
        fn()
    return (time.process_time() - c) / n * 1000


def warps() -> dict[str, Callable[[], Any]]:
    """OpenCV warps of a 900 x 700 ground patch to 640 x 480 at the scale and tilt
    a frame has (a texel about a pixel)."""
    rng = np.random.default_rng(1)
    patch = cv2.GaussianBlur(rng.integers(0, 256, (700, 900, 4), np.uint8), (5, 5), 0)
    one, three = np.ascontiguousarray(patch[..., 0]), np.ascontiguousarray(patch[..., :3])
    M = np.array([[1.1, 0.05, 100.0], [-0.04, 1.08, 50.0], [1e-5, 2e-5, 1.0]])
    size, inv = (640, 480), cv2.WARP_INVERSE_MAP
    out4, out3 = np.empty((480, 640, 4), np.uint8), np.empty((480, 640, 3), np.uint8)
    out1 = np.empty((480, 640), np.uint8)
    rep = cv2.BORDER_REPLICATE
    return {
        "bilinear BGRA perspective (the renderer's)": lambda: cv2.warpPerspective(
            patch, M, size, dst=out4, flags=cv2.INTER_LINEAR | inv, borderMode=rep),
        "bilinear, one channel": lambda: cv2.warpPerspective(
            one, M, size, dst=out1, flags=cv2.INTER_LINEAR | inv, borderMode=rep),
        "bilinear, three channels": lambda: cv2.warpPerspective(
            three, M, size, dst=out3, flags=cv2.INTER_LINEAR | inv, borderMode=rep),
        "bilinear BGRA affine": lambda: cv2.warpAffine(
            patch, M[:2], size, dst=out4, flags=cv2.INTER_LINEAR | inv, borderMode=rep),
        "nearest BGRA perspective (aliases)": lambda: cv2.warpPerspective(
            patch, M, size, dst=out4, flags=cv2.INTER_NEAREST | inv, borderMode=rep),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args()
    cv2.setNumThreads(1)
    frames = frames_of(a.frames)
    yuvs = [cv2.cvtColor(f, cv2.COLOR_BGRA2YUV_I420) for f in frames]
    enc: dict[str, list[float]] = {k: [] for k in ENCODERS}
    quality: dict[str, tuple[int, float, int]] = {}
    missing: dict[str, str] = {}
    conv: list[float] = []
    warp_fns = warps()
    warp: dict[str, list[float]] = {k: [] for k in warp_fns}
    yuv = np.empty_like(yuvs[0])
    with tempfile.TemporaryDirectory() as d:
        for _ in range(a.rounds):
            for name, (encoder, options, context, ext) in ENCODERS.items():
                if name in missing:
                    continue
                path = os.path.join(d, f"clip.{ext}")
                try:
                    enc[name].append(encode(yuvs, encoder, options, context, path))
                except (av.FFmpegError, ValueError) as e:  # an encoder this build lacks
                    missing[name] = str(e)
                    continue
                if name not in quality:
                    quality[name] = (os.path.getsize(path), *psnr_y(path, yuvs))
            conv.append(per_call_ms(lambda: [cv2.cvtColor(f, cv2.COLOR_BGRA2YUV_I420, dst=yuv)
                                             for f in frames], 1) / len(frames))
            for name, fn in warp_fns.items():
                warp[name].append(per_call_ms(fn, len(frames)))
    print(f"{len(frames)} frames 640x480 from render_bench's camera, min of {a.rounds} "
          "rounds, ms CPU a frame (one thread):")
    for name, ms in enc.items():
        if name in missing:
            print(f"  encoder {name:40s} not available here: {missing[name]}")
            continue
        size, db, n = quality[name]
        print(f"  encoder {name:40s} {min(ms):5.2f} ms  {size / 2**20:5.2f} MB  "
              f"luma PSNR {db:5.2f} dB ({n} frames decoded)")
    print(f"  colour conversion BGRA -> YUV 4:2:0{'':14s} {min(conv):5.2f} ms")
    for name, ms in warp.items():
        print(f"  warp {name:43s} {min(ms):5.2f} ms")
    floor = (min(enc[next(iter(ENCODERS))]) + min(conv)
             + min(warp["bilinear BGRA perspective (the renderer's)"]))
    print(f"floor of a frame with these libraries (mpeg4 q4 + conversion + bilinear BGRA "
          f"warp): {floor:.2f} ms")


if __name__ == "__main__":
    main()
