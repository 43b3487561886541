"""The scenario's ``ground:``, ``targets:`` and ``cameras:`` sections -> frozen specs.

Each parser takes ``(info: SectionInfo, node, path)``, reports every problem
through ``info`` (file:line: path: message, all at once) and never raises
for bad input. The camera rate is checked against the loop here: a frame is
only ever rendered at an exchange tick, so its period must be a whole number
of exchanges.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, replace
from typing import Any

from cosim.core.camera import CameraSpec
from cosim.core.geo import MAX_DISTANCE_M
from cosim.guidance.commands import GIMBAL_PITCH_DEG, GIMBAL_YAW_DEG
from cosim.renderer import imagery
from cosim.scenario.limits import MAX_NAME_CHARS, MIN_EXCHANGE_HZ
from cosim.scenario.schema import SectionInfo
from cosim.vehicles import get_class

P = tuple[Any, ...]
#: camera names and target ids become parts of file names (as vehicle ids)
_NAME = re.compile(rf"^[A-Za-z0-9_\-][A-Za-z0-9_.\-]{{0,{MAX_NAME_CHARS - 1}}}$")

#: camera limits: each side, and the pixels of one frame (8K UHD); every
#: stream keeps a frame buffer and its render worker a ground patch of this size
MAX_SIDE_PX = 8192
MAX_FRAME_PX = 7680 * 4320
MAX_IN_FLIGHT = 1024
MAX_RENDER_WORKERS = 64
#: targets: the largest box side (m)
MAX_TARGET_M = 1000.0

MOUNTS = ("nadir", "forward", "gimbal")  # gimbal: starts at nadir, commands point it
CODECS = ("mp4v", "h264", "mjpg")
TARGET_KINDS = ("truck", "fire_truck", "car", "person", "fire")

#: kind -> (length_m, width_m, height_m, (r, g, b)) defaults
TARGET_DEFAULTS: dict[str, tuple[float, float, float, tuple[int, int, int]]] = {
    "truck": (10.0, 2.5, 3.5, (200, 200, 195)),  # white box truck
    "fire_truck": (10.0, 2.5, 3.2, (220, 20, 25)),  # signal red with a yellow-green band
    "car": (4.5, 1.8, 1.5, (40, 70, 160)),
    "person": (0.5, 0.4, 1.75, (200, 120, 40)),
    "fire": (8.0, 8.0, 3.0, (255, 120, 0)),  # burning patch; the smoke rises above it
}


@dataclass(frozen=True)
class GroundSpec:
    """The ground texture. ``kind`` procedural: generated from the scenario seed;
    ``image``: a north-up picture whose top-left corner is at ``origin_ne_m``
    (local frame metres) with ``m_per_px``, or a GeoTIFF (``geotiff``) placed by
    its own tags; outside it the procedural ground."""

    kind: str = "procedural"
    image: str | None = None
    origin_ne_m: tuple[float, float] | None = None  # top-left corner (north, east)
    origin_latlon_deg: tuple[float, float] | None = None  # or its lat/lon
    m_per_px: float = 1.0
    geotiff: bool = False  # placed by the file's own georeference (cosim/renderer/geotiff.py)
    base_m_per_px: float = 0.05  # finest procedural level (no blur at 30 m)
    tile_px: int = 256
    max_range_m: float = 5000.0  # ground farther than this is drawn as haze/sky
    #: the folders the image and the files it names must lie in (resolved); empty:
    #: the image's own folder
    image_folders: tuple[str, ...] = ()

    def image_roots(self) -> tuple[str, ...]:
        """The folders the image and the files it names may be read from."""
        assert self.image is not None
        return self.image_folders or imagery.folders(os.path.dirname(self.image))


@dataclass(frozen=True)
class TargetSpec:
    id: str
    kind: str
    north_m: float | None
    east_m: float | None
    lat_deg: float | None
    lon_deg: float | None
    heading_deg: float
    length_m: float
    width_m: float
    height_m: float
    color_rgb: tuple[int, int, int]
    #: a fire's burning patch grows this fast in length and width (m/s)
    growth_m_per_s: float = 0.0

    def at(self, time_s: float) -> TargetSpec:
        """The target as it is at ``time_s`` (a growing fire's patch larger)."""
        if not self.growth_m_per_s:
            return self
        grow = self.growth_m_per_s * max(0.0, time_s)
        return replace(self, length_m=self.length_m + grow, width_m=self.width_m + grow,
                       growth_m_per_s=0.0)


@dataclass(frozen=True)
class CamerasSpec:
    views: tuple[CameraSpec, ...]
    codec: str = "mp4v"
    render_workers: int | None = None  # None: one per CPU, at most one per camera; 0: inline
    operator_view: bool = False
    operator_width_px: int = 960
    digest: bool = False  # record a sha256 of every camera's raw frames in summary.json
    max_in_flight: int = 64  # frames queued per render worker before the loop waits


def _rgb(info: SectionInfo, v: Any, path: P) -> tuple[int, int, int] | None:
    if isinstance(v, str) and re.match(r"^#[0-9a-fA-F]{6}$", v):
        return int(v[1:3], 16), int(v[3:5], 16), int(v[5:7], 16)
    if (isinstance(v, list) and len(v) == 3
            and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in v)):
        return int(v[0]), int(v[1]), int(v[2])
    info.err(path, f"expected a colour as '#rrggbb' or [r, g, b] (0-255), got {v!r}")
    return None


def parse_ground(info: SectionInfo, node: Any, path: P) -> GroundSpec:
    r = info.reader(node, path, ("texture", "image", "image_folders", "origin", "m_per_px",
                                 "base_m_per_px", "tile_px", "max_range_m"))
    kind = r.string("texture", "image" if r.has("image") else "procedural",
                    choices=("procedural", "image"))
    base = r.num("base_m_per_px", 0.05, lo=0.005, hi=10.0)
    tile = r.integer("tile_px", 256, lo=32, hi=4096)
    max_range = r.num("max_range_m", 5000.0, lo=100.0, hi=MAX_DISTANCE_M)
    image: str | None = None
    o_ne: tuple[float, float] | None = None
    o_ll: tuple[float, float] | None = None
    mpp = 1.0
    geotiff = False
    listed = _image_folders(info, r.d.get("image_folders"), path + ("image_folders",))
    if kind == "image":
        raw = r.string("image")
        if raw is not None:
            # a TIFF or VRT without origin and m_per_px must place itself (GeoTIFF)
            geotiff = os.path.splitext(raw)[1].lower() in (".tif", ".tiff", ".vrt") and \
                not (r.has("origin") or r.has("m_per_px"))
            image = _check_image(info, raw, listed, geotiff, path)
        if not geotiff:
            mpp = r.num("m_per_px", lo=0.0, lo_open=True, hi=10_000.0) or 1.0
            o = info.reader(r.d.get("origin"), path + ("origin",),
                            ("north_m", "east_m", "lat_deg", "lon_deg"))
            if o.has("lat_deg") or o.has("lon_deg"):
                la, lo = o.num("lat_deg", lo=-90, hi=90), o.num("lon_deg", lo=-180, hi=180)
                if la is not None and lo is not None:
                    o_ll = (la, lo)
            else:
                n = o.num("north_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
                e = o.num("east_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
                if n is not None and e is not None:
                    o_ne = (n, e)
    elif r.has("image"):
        info.err(path + ("image",), "an image needs 'texture: image'")
    return GroundSpec(kind=kind or "procedural", image=image, origin_ne_m=o_ne,
                      origin_latlon_deg=o_ll, m_per_px=mpp, geotiff=geotiff,
                      base_m_per_px=base or 0.05,
                      tile_px=tile or 256, max_range_m=max_range or 5000.0,
                      image_folders=imagery.folders(info.path.resolve().parent, listed))


def _image_folders(info: SectionInfo, node: Any, path: P) -> tuple[str, ...]:
    """``image_folders``: folders besides the scenario's from which a ground image
    and the files it names may be read (relative to the scenario's folder)."""
    if node is None:
        return ()
    if not isinstance(node, list) or len(node) > imagery.MAX_IMAGE_FOLDERS \
            or not all(isinstance(f, str) and f and "\0" not in f and len(f) <= 4096
                       for f in node):
        info.err(path, f"expected a list of at most {imagery.MAX_IMAGE_FOLDERS} folder names")
        return ()
    out = []
    for i, f in enumerate(node):
        p = str(info.path.resolve().parent / f)
        why = imagery.check_folder(p)
        if why is not None:
            info.err(path + (i,), why)
        else:
            out.append(p)
    return tuple(out)


def _check_image(info: SectionInfo, raw: str, listed: tuple[str, ...], geotiff: bool,
                 path: P) -> str | None:
    """The image's resolved path, once it and everything it names are allowed
    (cosim.renderer.imagery) and, for a TIFF or VRT, GDAL has read its metadata
    (``_check_geotiff``); None if a problem was reported."""
    roots = imagery.folders(info.path.resolve().parent, listed)
    name = str(info.path.resolve().parent / raw)
    suffix = os.path.splitext(raw)[1].lower()
    try:
        if geotiff or suffix == ".vrt":  # read by GDAL, with what it names
            real = imagery.check_georeferenced(name, roots)
        else:  # decoded whole
            real = imagery.check_picture(name, roots)
    except imagery.ImageRefused as e:
        info.err(path + ("image",), str(e))
        return None
    if suffix in (".tif", ".tiff", ".vrt"):
        _check_geotiff(info, real, geotiff, path)
    if not geotiff and suffix != ".vrt" and not _decodes(real):
        info.err(path + ("image",), f"cannot read {real} as an image (its pixels: cut short "
                                    "or damaged?)")
    return real


def _decodes(picture: str) -> bool:
    """Whether OpenCV decodes the picture (its size already bounded), as every
    render worker will."""
    import cv2
    from cv2.utils import logging as cv_log

    level = cv_log.getLogLevel()
    cv_log.setLogLevel(cv_log.LOG_LEVEL_SILENT)  # the message says it, once
    try:
        return cv2.imread(picture, cv2.IMREAD_REDUCED_COLOR_8) is not None
    finally:
        cv_log.setLogLevel(level)


def _check_geotiff(info: SectionInfo, image: str, geotiff: bool, path: P) -> None:
    """Report what stops the TIFF or VRT ``image`` from being used: as a
    georeferenced file (placed by its own georeference: ``geotiff``; only its
    metadata is read here) or as a picture placed by origin and m_per_px."""
    from cosim.renderer import geotiff as gt

    try:
        ref = gt.read_georef(image)
    except gt.GeoTiffError as e:
        if geotiff:  # neither georeferenced nor placed by hand
            info.err(path + ("image",), str(e))
        elif image.lower().endswith(".vrt"):
            info.err(path + ("image",), f"{e} (a VRT is read by GDAL, placed by its own "
                                        "georeference; a picture must be PNG, JPG or TIFF)")
        return
    if not geotiff:
        info.err(path, f"{image} is a GeoTIFF and carries its own georeference: leave out "
                       "origin and m_per_px")
        return
    why = gt.check_crs(ref) or gt.probe(image)
    if why is not None:
        info.err(path + ("image",), f"{image}: {why}")


def parse_targets(info: SectionInfo, node: Any, path: P) -> tuple[TargetSpec, ...]:
    if not isinstance(node, list):
        info.err(path, "expected a list of targets")
        return ()
    out: list[TargetSpec] = []
    seen: set[str] = set()
    for i, d in enumerate(node):
        p = path + (i,)
        r = info.reader(d, p, ("id", "kind", "north_m", "east_m", "lat_deg", "lon_deg",
                               "heading_deg", "length_m", "width_m", "height_m", "color",
                               "growth_m_per_min"))
        kind = r.string("kind", choices=TARGET_KINDS)
        tid = r.string("id", f"{kind or 'target'}{i}", pattern=_NAME)
        if tid is not None and tid in seen:
            info.err(p + ("id",), f"duplicate target id {tid!r}")
        seen.add(tid or "")
        n = e = la = lo = None
        if r.has("lat_deg") or r.has("lon_deg"):
            if r.has("north_m") or r.has("east_m"):
                info.err(p, "give north_m/east_m or lat_deg/lon_deg, not both")
            la, lo = r.num("lat_deg", lo=-90, hi=90), r.num("lon_deg", lo=-180, hi=180)
        else:
            n = r.num("north_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
            e = r.num("east_m", lo=-MAX_DISTANCE_M, hi=MAX_DISTANCE_M)
        dl, dw, dh, dc = TARGET_DEFAULTS.get(kind or "truck", TARGET_DEFAULTS["truck"])
        color = _rgb(info, r.d["color"], p + ("color",)) if r.has("color") else dc
        out.append(TargetSpec(
            id=tid or f"target{i}", kind=kind or "truck", north_m=n, east_m=e, lat_deg=la,
            lon_deg=lo, heading_deg=r.num("heading_deg", 0.0, lo=-360, hi=360) or 0.0,
            length_m=r.num("length_m", dl, lo=0.0, lo_open=True, hi=MAX_TARGET_M) or dl,
            width_m=r.num("width_m", dw, lo=0.0, lo_open=True, hi=MAX_TARGET_M) or dw,
            height_m=r.num("height_m", dh, lo=0.0, lo_open=True, hi=MAX_TARGET_M) or dh,
            color_rgb=color or dc,
            growth_m_per_s=(r.num("growth_m_per_min", 0.0, lo=0.0, hi=100.0) or 0.0) / 60.0))
        if out[-1].growth_m_per_s and out[-1].kind != "fire":
            info.err(p + ("growth_m_per_min",), "only a fire grows")
    return tuple(out)


def _frame_every(info: SectionInfo, rate_hz: float, p: P) -> int:
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


def _camera(info: SectionInfo, d: Any, p: P, i: int) -> CameraSpec | None:
    r = info.reader(d, p, ("name", "vehicles", "mount", "stabilised", "hfov_deg", "vfov_deg",
                           "width_px", "height_px", "rate_hz"))
    name = r.string("name", f"cam{i}", pattern=_NAME)
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
    if None in (name, w, h, rate) or not every:
        return None
    return CameraSpec(name=name, vehicles=tuple(rows), mount=mount, pitch_deg=pitch,
                      yaw_deg=yaw, stabilised=stab, hfov_deg=hfov, vfov_deg=vfov, width_px=w,
                      height_px=h, rate_hz=rate, frame_every=every)


def parse_cameras(info: SectionInfo, node: Any, path: P) -> CamerasSpec:
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
            cam = _camera(info, d, path + ("views", i), i)
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
