"""The scenario's ``cameras:`` section -> frozen ``CamerasSpec``.

The parser takes ``(info: SectionContext, node, path)``, reports every problem
through ``info`` (file:line: path: message, all at once) and never raises
for bad input. The camera rate is checked against the loop here: a frame is
only ever rendered at an exchange tick, so its period must be a whole number
of exchanges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from cosim.core.camera import CameraSpec, SensorSpec
from cosim.core.limits import MIN_EXCHANGE_HZ
from cosim.core.section import SectionContext
from cosim.guidance.commands import GIMBAL_PITCH_DEG, GIMBAL_YAW_DEG
from cosim.vehicles import get_class
from cosim.world.targets import NAME

P = tuple[Any, ...]

#: camera limits: each side, and the pixels of one frame (8K UHD); every
#: stream keeps a frame buffer and its render worker a ground patch of this size
MAX_SIDE_PX = 8192
MAX_FRAME_PX = 7680 * 4320
MAX_IN_FLIGHT = 1024
MAX_RENDER_WORKERS = 64
MOUNTS = ("nadir", "forward", "gimbal")  # gimbal: starts at nadir, commands point it
CODECS = ("mp4v", "h264", "mjpg")
#: sensor limits: vignetting's power of cos^4, the signal-to-noise ratio at
#: mid-grey and the ISO setting (40 dB at ISO 100, 3 dB less per doubling)
MAX_VIGNETTING = 4.0
MAX_SNR_DB = 80.0
MIN_ISO, MAX_ISO = 25.0, 102400.0
#: radial distortion's k1, k2 at most this in size (and never folding the image)
MAX_K = 1.0
#: the longest exposure (motion blur), ms
MAX_EXPOSURE_MS = 100.0
@dataclass(frozen=True)
class CamerasSpec:
    views: tuple[CameraSpec, ...]
    codec: str = "mp4v"
    render_workers: int | None = None  # None: one per CPU, at most one per camera; 0: inline
    operator_view: bool = False
    operator_width_px: int = 960
    digest: bool = False  # record a sha256 of every camera's raw frames in summary.json
    max_in_flight: int = 64  # frames queued per render worker before the loop waits


def _frame_every(info: SectionContext, rate_hz: float, p: P) -> int:
    """Physics ticks per frame; reports a rate whose period is neither a whole
    number of exchanges (frames rendered from an exchange's states) nor a
    whole fraction of one (the camera's aircraft gathered inside each
    exchange at the frame rate)."""
    hz, k = info.rates.physics_hz, info.rates.control_every
    fits = sorted({hz / (k * m) for m in range(1, 5)} | {hz * m / k for m in range(2, 5)
                                                         if k % m == 0}, reverse=True)
    ok = ", ".join(f"{r:g}" for r in fits)
    every = hz / rate_hz
    if abs(every - round(every)) > 1e-9:
        info.err(p, f"rate_hz {rate_hz:g} must divide physics_hz {hz:g}, and frames must fall "
                    f"on exchanges or evenly between them (every {k} ticks); rates that fit: "
                    f"{ok}, ...")
        return 0
    n = round(every)
    if n % k and k % n:
        info.err(p, f"rate_hz {rate_hz:g}: a frame every {n} ticks neither falls on exchanges "
                    f"nor divides one (control_hz {info.rates.control_hz:g} = every {k} "
                    f"ticks); use one of {ok}, ... or change rates.control_hz")
        return 0
    return n


def parse_camera(info: SectionContext, d: Any, p: P, i: int) -> CameraSpec | None:
    """One camera's node (a view of ``cameras:``, or a section's own camera such
    as the search's), ``i``-th of its list; None if a problem was reported."""
    r = info.reader(d, p, ("name", "vehicles", "mount", "stabilised", "hfov_deg", "vfov_deg",
                           "width_px", "height_px", "rate_hz", "sensor", "datalink"))
    name = r.string("name", f"cam{i}", pattern=NAME)
    rows = info.select(r.d.get("vehicles", "all"), p + ("vehicles",))
    mount_raw = r.d.get("mount")
    if mount_raw is None:  # the vehicles' class's own mount
        defaults = sorted({get_class(info.vehicles[row].vehicle_class).default_camera_mount
                           for row in rows}) or ["nadir"]
        if len(defaults) > 1:
            info.err(p, f"its vehicles' classes mount cameras differently ({', '.join(defaults)})"
                        f": give mount:")
        mount_raw = defaults[0]
    mount, pitch, yaw = "nadir", -90.0, 0.0
    if isinstance(mount_raw, dict):  # a gimbal at these angles
        m = info.reader(mount_raw, p + ("mount",), ("pitch_deg", "yaw_deg"))
        pitch = m.num("pitch_deg", GIMBAL_PITCH_DEG[0], lo=GIMBAL_PITCH_DEG[0],
                      hi=GIMBAL_PITCH_DEG[1]) or 0.0
        yaw = m.num("yaw_deg", 0.0, lo=GIMBAL_YAW_DEG[0], hi=GIMBAL_YAW_DEG[1]) or 0.0
        mount = "gimbal"
    elif mount_raw in MOUNTS:
        mount = str(mount_raw)
        pitch = 0.0 if mount == "forward" else -90.0
    else:
        info.err(p + ("mount",), f"expected nadir, forward, gimbal or {{pitch_deg: N, "
                                 f"yaw_deg: N}}, got {mount_raw!r}")
    w = r.integer("width_px", 640, lo=16, hi=MAX_SIDE_PX)
    h = r.integer("height_px", 480, lo=16, hi=MAX_SIDE_PX)
    if w is not None and h is not None and w * h > MAX_FRAME_PX:
        info.err(p, f"{w}x{h} is {w * h / 1e6:.1f} Mpx a frame; at most "
                    f"{MAX_FRAME_PX / 1e6:.1f} Mpx (7680x4320)")
        w = None
    which = r.one_of("hfov_deg", "vfov_deg")
    fov = r.num(which or "hfov_deg", 60.0, lo=1.0, hi=170.0)
    hfov = vfov = 60.0
    if w is not None and h is not None and fov is not None:
        t = math.tan(math.radians(fov) / 2)
        if which == "vfov_deg":
            vfov, hfov = fov, math.degrees(2 * math.atan(t * w / h))
        else:
            hfov, vfov = fov, math.degrees(2 * math.atan(t * h / w))
        if max(hfov, vfov) >= 175.0:
            info.err(p + (which or "hfov_deg",), f"the other field of view would be "
                                                 f"{max(hfov, vfov):.0f} deg; keep both under 175")
    rate = r.num("rate_hz", 10.0, lo=MIN_EXCHANGE_HZ, hi=info.rates.physics_hz)
    every = _frame_every(info, rate, p + ("rate_hz",)) if rate is not None else 0
    stab = r.boolean("stabilised", False)
    sensor = None
    if r.d.get("sensor") is not None:
        r_max = math.hypot(math.tan(math.radians(hfov) / 2), math.tan(math.radians(vfov) / 2))
        sensor = parse_sensor(info, r.d["sensor"], p + ("sensor",), r_max)
    link = None
    if r.d.get("datalink") is not None:
        from cosim.renderer.datalink import parse_datalink

        link = parse_datalink(info, r.d["datalink"], p + ("datalink",), rate if every else None,
                              (w, h))
        if link is None:
            return None
    if None in (name, w, h, rate) or not every:
        return None
    return CameraSpec(name=name, vehicles=tuple(rows), mount=mount, pitch_deg=pitch,
                      yaw_deg=yaw, stabilised=stab, hfov_deg=hfov, vfov_deg=vfov, width_px=w,
                      height_px=h, rate_hz=rate, frame_every=every, sensor=sensor,
                      datalink=link)


def parse_sensor(info: SectionContext, d: Any, p: P, r_max: float) -> SensorSpec | None:
    """A camera's ``sensor:`` (every key optional; ``sensor.SensorSpec``), for an
    image whose corner lies ``r_max`` from its centre in normalised
    coordinates; None if a problem was reported."""
    from cosim.renderer.sensor import folds_at, snr_of_iso

    r = info.reader(d, p, ("vignetting", "snr_db", "iso", "distortion", "exposure_ms"))
    exposure = r.num("exposure_ms", 0.0, lo=0.0, hi=MAX_EXPOSURE_MS)
    k1: float | None = 0.0
    k2: float | None = 0.0
    if r.has("distortion"):
        dr = info.reader(r.d["distortion"], p + ("distortion",), ("k1", "k2"))
        k1 = dr.num("k1", 0.0, lo=-MAX_K, hi=MAX_K)
        k2 = dr.num("k2", 0.0, lo=-MAX_K, hi=MAX_K)
        if k1 is not None and k2 is not None and (r_fold := folds_at(k1, k2, r_max)):
            info.err(p + ("distortion",),
                     f"k1 {k1:g}, k2 {k2:g} fold the image: the distorted radius stops growing "
                     f"at r = {r_fold:.3f}, inside the image's corner at r = {r_max:.3f} "
                     f"(normalised; 1 + 3 k1 r^2 + 5 k2 r^4 must stay above 0 up to it); "
                     f"use smaller k1, k2")
            k1 = None
    vig_raw = r.d.get("vignetting", 0.0)
    vig: float | None = 0.0
    if vig_raw == "cos4" or vig_raw is True:
        vig = 1.0
    elif vig_raw is False:
        vig = 0.0
    elif not isinstance(vig_raw, str):
        vig = r.num("vignetting", 0.0, lo=0.0, hi=MAX_VIGNETTING)
    else:
        info.err(p + ("vignetting",), f"expected cos4, true, false or a strength 0 to "
                                      f"{MAX_VIGNETTING:g} (the power of cos^4), "
                                      f"got {vig_raw!r}")
        vig = None
    snr: float | None = None
    which = r.one_of("snr_db", "iso")
    if which == "iso":
        iso = r.num("iso", None, lo=MIN_ISO, hi=MAX_ISO)
        snr = snr_of_iso(iso) if iso is not None else None
    elif which == "snr_db":
        snr = r.num("snr_db", None, lo=0.0, hi=MAX_SNR_DB)
    if vig is None or (which and snr is None) or k1 is None or k2 is None or exposure is None:
        return None
    return SensorSpec(vignetting=vig, snr_db=snr, k1=k1, k2=k2, exposure_ms=exposure)


def parse_cameras(info: SectionContext, node: Any, path: P) -> CamerasSpec:
    """``cameras: [camera, ...]`` or ``cameras: {views: [...], codec, render_workers,
    operator_view, digest}``."""
    if isinstance(node, list):
        node = {"views": node}
    r = info.reader(node, path, ("views", "codec", "render_workers", "operator_view",
                                 "operator_width_px", "digest", "max_in_flight"))
    codec = r.string("codec", "mp4v", choices=CODECS)
    from cosim.renderer.video import have_pyav

    if codec == "h264" and not have_pyav():
        info.err(path + ("codec",), "h264 needs PyAV (pip install av); OpenCV's wheels have "
                                    "no H.264 encoder (mp4v and mjpg work without it)")
    workers = r.integer("render_workers", None, lo=0, hi=MAX_RENDER_WORKERS)
    views_raw = r.d.get("views")
    views: list[CameraSpec] = []
    if not isinstance(views_raw, list) or not views_raw:
        info.err(path + ("views",), "expected a non-empty list of cameras")
    else:
        names: set[str] = set()
        for i, d in enumerate(views_raw):
            cam = parse_camera(info, d, path + ("views", i), i)
            if cam is None:
                continue
            if cam.name in names:
                info.err(path + ("views", i, "name"), f"duplicate camera name {cam.name!r}")
            names.add(cam.name)
            views.append(cam)
    return CamerasSpec(views=tuple(views), codec=codec or "mp4v", render_workers=workers,
                       operator_view=r.boolean("operator_view", False),
                       operator_width_px=r.integer("operator_width_px", 960, lo=160,
                                                   hi=7680) or 960,
                       digest=r.boolean("digest", False),
                       max_in_flight=r.integer("max_in_flight", 64, lo=1,
                                               hi=MAX_IN_FLIGHT) or 64)
