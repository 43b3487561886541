"""The camera pipeline's levers, each timed A against B in the same run (not a test).

For a 640x480 frame, each variant of a step runs in turn on the same frame,
round after round, so the machine's load falls on A and B alike; the median
of each is printed (ms, wall clock; the datalink's also in process CPU time,
which counts every encoder thread):

- vignetting and noise: ``Sensor.apply`` with ``vignetting`` and ``snr_db``
  (committed: one compiled pass, ``sensor_pass``, its levels from splitmix64)
  against the OpenCV and numpy passes before it (cv2.multiply of the BGRA
  frame by a float32 gain, a colour conversion, PCG64's raw words as levels,
  interleaved with the values by cv2.merge, np.take in pieces of 65,536
  values, the conversion back), each effect alone and both;
- vignetting: cv2.multiply of the BGRA frame by the float32 gain against the
  same on three channels after a colour conversion, and numpy in float32;
- distortion: cv2.remap with float32 maps (committed) against OpenCV's
  fixed-point maps;
- motion blur (3.4 px down the columns): cv2.filter2D (committed) against
  cv2.sepFilter2D;
- haze: the compiled sweep (committed: each 4 x 32 tile through its own
  table, ``haze_pass``; here every tile the same level) against cv2.LUT with a
  four-channel table over the frame, one table for every channel and three
  channels after a colour conversion;
- datalink: ``Downlink.send`` (x264 ultrafast, one encoder thread, the frame
  handed over as a view of the converted buffer: committed) against a copy of
  it (from_ndarray; the two videos are checked to be the same bytes) and
  against two encoder threads.

    python benchmarks/imagery_levers.py [--rounds 60]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cosim.core.camera import CameraSpec, DatalinkSpec, SensorSpec
from cosim.renderer.datalink import Downlink
from cosim.renderer.sensor import (
    GAMMA,
    Sensor,
    distortion_maps,
    frame_rng,
    line_kernel,
    noise_table,
    off_axis_cos,
)

W, H = 640, 480


def _frame(shift_px: int = 0) -> np.ndarray:
    """A BGRA frame of smooth texture (a ground-like spectrum), moved ``shift_px``
    down."""
    rng = np.random.default_rng(0)
    big = rng.integers(0, 256, (H + 64, W, 4), dtype=np.uint8)
    big = np.asarray(cv2.GaussianBlur(big, (7, 7), 0), np.uint8)
    out = np.ascontiguousarray(big[32 - shift_px % 32:32 - shift_px % 32 + H])
    out[..., 3] = 255
    return out


def _cam(sensor: SensorSpec) -> CameraSpec:
    """A 640x480 nadir camera with an 80 deg lens and ``sensor``."""
    return CameraSpec(name="c", vehicles=(0,), mount="nadir", pitch_deg=-90.0,
                      stabilised=True, hfov_deg=80.0, vfov_deg=64.0, width_px=W,
                      height_px=H, rate_hz=15.0, frame_every=4, sensor=sensor)


def _ab(variants: Mapping[str, Callable[[int], object]], rounds: int,
        clock: Callable[[], float] = time.perf_counter) -> dict[str, float]:
    """Median ms of each variant, called in turn ``rounds`` times (with the round)."""
    times: dict[str, list[float]] = {k: [] for k in variants}
    for i in range(rounds):
        for name, fn in variants.items():
            t = clock()
            fn(i)
            times[name].append(clock() - t)
    return {k: 1e3 * statistics.median(v) for k, v in times.items()}


_TAKE_CHUNK = 65536
_HIGH = 1 if sys.byteorder == "little" else 0


def _gain4(cam: CameraSpec) -> np.ndarray:
    """The vignetting's float32 BGRA gain (alpha 1), as cv2.multiply takes it."""
    assert cam.sensor is not None
    v = (off_axis_cos(cam) ** (4.0 * cam.sensor.vignetting / GAMMA)).astype(np.float32)
    return np.dstack([v, v, v, np.ones_like(v)])


class _OpenCVSensor:
    """Vignetting and noise as OpenCV and numpy passes (before ``sensor_pass``):
    cv2.multiply, a colour conversion, PCG64's raw words as levels interleaved
    with the values by cv2.merge, np.take in pieces, the conversion back."""

    def __init__(self, cam: CameraSpec) -> None:
        assert cam.sensor is not None
        self.cam, self.spec = cam, cam.sensor
        self.gain = _gain4(cam) if self.spec.vignetting else None
        self.table = noise_table(self.spec.snr_db) if self.spec.snr_db is not None else None
        self.bgr = np.empty((H, W, 3), np.uint8)
        self.pairs = np.empty((H, W * 3, 2), np.uint8)

    def apply(self, img: np.ndarray, frame_no: int) -> np.ndarray:
        if self.gain is not None:
            cv2.multiply(img, self.gain, dst=img, dtype=cv2.CV_8U)
        if self.table is not None:
            bgr = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR, dst=self.bgr)
            rng = frame_rng(1, 0, self.cam.name, frame_no)
            n = bgr.size
            levels = rng.bit_generator.random_raw(-(-n // 8)).view(np.uint8)[:n]
            flat = bgr.reshape(-1)
            pair = [flat.reshape(H, -1), levels.reshape(H, -1)]
            cv2.merge(pair[::-1] if _HIGH else pair, dst=self.pairs)
            idx = self.pairs.view(np.uint16).reshape(-1)
            for i in range(0, n, _TAKE_CHUNK):
                np.take(self.table, idx[i:i + _TAKE_CHUNK], out=flat[i:i + _TAKE_CHUNK])
            cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA, dst=img)
        return img


def noise(rounds: int) -> dict[str, float]:
    base = _frame()
    out: dict[str, float] = {}
    for what, spec in (("vignetting", SensorSpec(vignetting=1.0)),
                       ("noise", SensorSpec(snr_db=40.0)),
                       ("vignetting + noise", SensorSpec(vignetting=1.0, snr_db=40.0))):
        cam = _cam(spec)
        fused, old = Sensor(cam, spec, seed=1, vehicle_row=0), _OpenCVSensor(cam)
        fused.apply(base.copy(), 0)  # numba compiles (or loads) it
        out.update(_ab({f"{what}, one compiled pass (committed)": _on(fused.apply, base),
                        f"{what}, OpenCV and numpy passes": _on(old.apply, base)}, rounds))
    return out


def _on(apply: Callable[[np.ndarray, int], np.ndarray], base: np.ndarray
        ) -> Callable[[int], object]:
    """A round's call of ``apply`` on a copy of ``base``."""
    return lambda i: apply(base.copy(), i)


def vignetting(rounds: int) -> dict[str, float]:
    cam = _cam(SensorSpec(vignetting=1.0))
    gain4 = _gain4(cam)
    gain3 = np.ascontiguousarray(gain4[..., :3])
    base = _frame()
    bgr = np.empty((H, W, 3), np.uint8)

    def bgra(_: int) -> None:
        img = base.copy()
        cv2.multiply(img, gain4, dst=img, dtype=cv2.CV_8U)

    def three(_: int) -> None:
        img = base.copy()
        cv2.cvtColor(img, cv2.COLOR_BGRA2BGR, dst=bgr)
        cv2.multiply(bgr, gain3, dst=bgr, dtype=cv2.CV_8U)

    def in_numpy(_: int) -> None:
        img = base.copy()
        f = img.astype(np.float32)
        f *= gain4
        img[:] = np.rint(f)

    return _ab({"vignetting, cv2.multiply BGRA": bgra,
                "vignetting, BGR after cvtColor": three,
                "vignetting, numpy float32": in_numpy}, rounds)


def distortion(rounds: int) -> dict[str, float]:
    cam = _cam(SensorSpec(k1=-0.05))
    base = _frame()
    out = np.empty_like(base)
    maps = {"float32 (committed)": distortion_maps(cam, -0.05, 0.0),
            "fixed point": distortion_maps(cam, -0.05, 0.0, fixed=True)}

    def remap(m: tuple[np.ndarray, np.ndarray]) -> Callable[[int], object]:
        return lambda _: cv2.remap(base, *m, cv2.INTER_LINEAR, dst=out,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 255))

    return _ab({f"distortion, cv2.remap, {k} maps": remap(m) for k, m in maps.items()}, rounds)


def blur(rounds: int) -> dict[str, float]:
    kernel, anchor = line_kernel(0.0, 3.4)  # 10 ms at 51.4 m/s, 100 m up: down the columns
    base = _frame()
    column = np.ones((1, 1), np.float32)

    def full(_: int) -> None:
        img = base.copy()
        cv2.filter2D(img, -1, kernel, dst=img, anchor=anchor, borderType=cv2.BORDER_REPLICATE)

    def separable(_: int) -> None:
        img = base.copy()
        cv2.sepFilter2D(img, -1, column, kernel.reshape(-1, 1), dst=img, anchor=anchor,
                        borderType=cv2.BORDER_REPLICATE)

    return _ab({"motion blur, cv2.filter2D (committed)": full,
                "motion blur, cv2.sepFilter2D": separable}, rounds)


def haze_lut(rounds: int) -> dict[str, float]:
    """The haze's table look-up over a whole frame: the compiled sweep of each
    pixel's interpolated transmittance (committed) against cv2.LUT with a
    four-channel table (the airlight's colour differs by channel), one table
    shared by the channels (what a grey airlight would allow) and three
    channels after a colour conversion."""
    from cosim.renderer.haze import TILE_COLS, TILE_ROWS
    from cosim.renderer.haze_pass import haze_smooth

    base = _frame()
    ramp = np.arange(256) // 2
    table4 = np.dstack([ramp + 10, ramp + 20, ramp + 30, np.arange(256)]).astype(np.uint8)
    table3 = np.ascontiguousarray(table4[..., :3])
    table1 = (ramp + 20).astype(np.uint8)
    bgr = np.empty((H, W, 3), np.uint8)
    tables = np.ascontiguousarray(table4)  # one level: (1, 256, 4)
    rows = np.array([(y, y + TILE_ROWS) for y in range(0, H, TILE_ROWS)], np.int64)
    yc = rows.mean(axis=1) - 0.5
    xc = np.arange(0, W, TILE_COLS) + (TILE_COLS - 1) / 2.0
    t_c = np.full((len(rows), len(xc)), 0.5)

    def swept(_: int) -> None:
        img = base.copy()
        haze_smooth(img, rows, yc, xc, t_c, tables)

    def four(_: int) -> None:
        img = base.copy()
        cv2.LUT(img, table4, dst=img)

    def shared(_: int) -> None:
        flat = base.copy().reshape(H, -1)
        cv2.LUT(flat, table1, dst=flat)

    def three(_: int) -> None:
        img = base.copy()
        cv2.cvtColor(img, cv2.COLOR_BGRA2BGR, dst=bgr)
        cv2.LUT(bgr, table3, dst=bgr)
        cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA, dst=img)

    swept(0)  # numba compiles (or loads) it
    return _ab({"haze, compiled sweep, interpolated (committed)": swept,
                "haze, cv2.LUT four-channel table": four,
                "haze, cv2.LUT one table for all channels": shared,
                "haze, cv2.LUT three channels after cvtColor": three}, rounds)


class _CopyingDownlink(Downlink):
    """``Downlink`` handing x264 a copy of the converted frame (from_ndarray), as
    before the frame was made over the buffer itself."""

    def picture(self) -> Any:
        import av

        return av.VideoFrame.from_ndarray(self.yuv, format="yuv420p")


def datalink(rounds: int) -> dict[str, float]:
    frames = [_frame(3 * k) for k in range(32)]
    spec = DatalinkSpec(codec="h264", bitrate_kbps=1000.0, rate_hz=15.0, every=1, gop=15,
                        latency_ms=0.0)
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        links = {"x264 1 thread, frame over the buffer (committed)":
                 Downlink(str(Path(tmp) / "a.mp4"), spec, W, H),
                 "x264 1 thread, frame copied": _CopyingDownlink(str(Path(tmp) / "b.mp4"),
                                                                 spec, W, H),
                 "x264 2 threads": Downlink(str(Path(tmp) / "c.mp4"), spec, W, H)}
        links["x264 2 threads"].stream.codec_context.thread_count = 2  # before it opens
        variants = {k: (lambda i, lk=lk: lk.send(frames[i % len(frames)]))
                    for k, lk in links.items()}
        wall = _ab(variants, rounds)
        cpu = _ab(variants, rounds, time.process_time)
        for link in links.values():
            link.close()
        if (Path(tmp) / "a.mp4").read_bytes() != (Path(tmp) / "b.mp4").read_bytes():
            raise SystemExit("datalink: the frame over the buffer gave another video")
    for k in wall:
        out[f"datalink send, {k}, wall"] = wall[k]
        out[f"datalink send, {k}, CPU"] = cpu[k]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=60)
    parts = {f.__name__: f for f in (noise, distortion, vignetting, blur, haze_lut, datalink)}
    ap.add_argument("--parts", default=",".join(parts),
                    help=f"comma-separated, of {', '.join(parts)} (default: all)")
    args = ap.parse_args(argv)
    unknown = set(args.parts.split(",")) - set(parts)
    if unknown:
        ap.error(f"--parts: unknown {', '.join(sorted(unknown))}; expected some of "
                 f"{', '.join(parts)}")
    cv2.setNumThreads(1)  # one core, as the render workers
    for part in (parts[k] for k in args.parts.split(",")):
        for name, ms in part(args.rounds).items():
            print(f"{name:72s} {ms:6.2f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
