"""The ground under the scenario: the ``ground:`` section -> ``GroundSpec``:
a procedural texture drawn from the scenario's seed, or an image (a north-up
picture placed by ``origin`` and ``m_per_px``, or a georeferenced GeoTIFF or
VRT placed by its own tags) with the procedural ground around it. Every file
an image names is checked before anything opens it (``imagery``), when the
scenario is read and again when the image is opened to be drawn
(``open_image``: a ``picture.Picture`` or a ``geotiff.GeoRaster``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from cosim.core.geo import MAX_DISTANCE_M, LocalFrame
from cosim.core.section import SectionContext
from cosim.errors import ConfigError
from cosim.world import imagery

if TYPE_CHECKING:
    from cosim.world.geotiff import GeoRaster
    from cosim.world.picture import Picture

P = tuple[Any, ...]
#: the ``trees`` a procedural ground may have
TREES = ("flat", "3d", "none")


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
    geotiff: bool = False  # placed by the file's own georeference (cosim/world/geotiff.py)
    base_m_per_px: float = 0.05  # finest procedural level (no blur at 30 m)
    tile_px: int = 256
    max_range_m: float = 5000.0  # ground farther than this is drawn as haze/sky
    #: the procedural ground's trees: "flat" (crowns in the texture), "3d" (crowns
    #: with height, drawn in perspective, hiding what is under them), "none"
    trees: str = "flat"
    #: the folders the image and the files it names must lie in (resolved); empty:
    #: the image's own folder
    image_folders: tuple[str, ...] = ()

    def image_roots(self) -> tuple[str, ...]:
        """The folders the image and the files it names may be read from."""
        assert self.image is not None
        return self.image_folders or imagery.folders(os.path.dirname(self.image))


def open_image(spec: GroundSpec, frame: LocalFrame) -> Picture | GeoRaster:
    """The ground's image, read to be drawn: a georeferenced file (``spec.geotiff``)
    opened by windows, or a picture decoded whole, each placed on the scenario
    ``frame``; what it may read is checked again first (the files may have
    changed since the scenario was read). ConfigError naming ``ground.image``
    if it cannot be."""
    from cosim.world import geotiff
    from cosim.world.picture import Picture

    assert spec.image is not None
    try:
        if spec.geotiff:
            imagery.check_georeferenced(spec.image, spec.image_roots())
            return geotiff.GeoRaster(spec.image, frame)
        return Picture(spec.image, spec.image_roots(), frame, spec.m_per_px, spec.origin_ne_m,
                       spec.origin_latlon_deg)
    except (geotiff.GeoTiffError, imagery.ImageRefused) as err:
        raise ConfigError(f"ground.image: {err}") from err


def parse_ground(info: SectionContext, node: Any, path: P) -> GroundSpec:
    r = info.reader(node, path, ("texture", "image", "image_folders", "origin", "m_per_px",
                                 "base_m_per_px", "tile_px", "max_range_m", "trees"))
    kind = r.string("texture", "image" if r.has("image") else "procedural",
                    choices=("procedural", "image"))
    base = r.num("base_m_per_px", 0.05, lo=0.005, hi=10.0)
    tile = r.integer("tile_px", 256, lo=32, hi=4096)
    max_range = r.num("max_range_m", 5000.0, lo=100.0, hi=MAX_DISTANCE_M)
    trees = r.string("trees", "flat", choices=TREES)
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
                      tile_px=tile or 256, max_range_m=max_range or 5000.0, trees=trees or "flat",
                      image_folders=imagery.folders(info.path.resolve().parent, listed))


def _image_folders(info: SectionContext, node: Any, path: P) -> tuple[str, ...]:
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


def _check_image(info: SectionContext, raw: str, listed: tuple[str, ...], geotiff: bool,
                 path: P) -> str | None:
    """The image's resolved path, once it and everything it names are allowed
    (cosim.world.imagery) and, for a TIFF or VRT, GDAL has read its metadata
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


def _check_geotiff(info: SectionContext, image: str, geotiff: bool, path: P) -> None:
    """Report what stops the TIFF or VRT ``image`` from being used: as a
    georeferenced file (placed by its own georeference: ``geotiff``; only its
    metadata is read here) or as a picture placed by origin and m_per_px."""
    from cosim.world import geotiff as gt

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
