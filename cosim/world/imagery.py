"""What a ground image may read, checked before GDAL or OpenCV opens anything.

A scenario names its ground image; a VRT names more files (its sources and
nested VRTs), and GDAL opens files beside each one (external overviews
``.ovr``, masks ``.msk``, world files). All of it is untrusted input.
``check_picture`` (a picture decoded whole by OpenCV) and
``check_georeferenced`` (a GeoTIFF or VRT read by GDAL) refuse, naming the
file (a VRT's line) and why:

- a name GDAL would not read as a plain local file: its virtual file systems
  (``/vsicurl/``, ``/vsizip/``, ...), URLs and driver prefixes (``vrt://``,
  ``GTIFF_DIR:``, ``DERIVED_SUBDATASET:``): any colon, ``<``, backslash or
  control character;
- a file that is not a regular file (a device, FIFO, socket or folder), or
  that lies, once symbolic links are followed, outside the allowed folders
  (``folders``: the scenario's own and those in ``ground.image_folders``);
  the same for the files GDAL opens beside a raster (``NAME.*``, ``STEM.*``);
- a file whose content is not what its name says, or not a TIFF, PNG, JPEG
  or VRT (GDAL picks its driver by the content, not by the name);
- a VRT that is not a plain mosaic. It is parsed here with expat (at most
  ``MAX_VRT_BYTES``; no DTD, entities, CDATA or processing instructions) and
  only the elements and attributes of plain bands and their sources are
  accepted, compared without case as GDAL compares them: no derived bands or
  pixel functions (no Python), no raw, warped, pansharpened or processed
  datasets, no kernel filters, no open options. Its sources are checked in
  turn: nested VRTs at most ``MAX_VRT_DEPTH`` deep, ``MAX_VRT_SOURCES`` in all;
- declared sizes a render worker cannot afford: a picture decoded whole
  (PNG, JPEG, or a TIFF placed by hand; also a PNG or JPEG inside a VRT,
  which GDAL may decode whole) of more than ``MAX_PICTURE_PX``; a block
  (a TIFF's tile or strip, a VRT band's block) of more than ``MAX_BLOCK_BYTES``,
  which GDAL decodes at once however small the window read; a georeferenced
  raster of more than ``MAX_RASTER_SIDE_PX`` a side. A large tiled GeoTIFF
  with overviews (a COG) is read by windows and is fine at any size within
  that.

Only headers are read (cosim/world/headers.py): nothing is decoded.
``GDAL_OPTIONS`` are the settings every
GDAL read runs under (cosim/world/geotiff.py), a second line of defence:
no network (``/vsicurl/`` and the cloud file systems see no file as
existing), no ``.aux.xml`` side files (their ``OVERVIEW_FILE`` may name any
path), no Python pixel functions, no raw VRT bands.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.world.headers import Header, ImageRefused, header, sniff

#: a picture decoded whole: every render worker holds it as BGRA with its
#: pyramid (64 Mpx: about 360 MB); larger ones belong in a tiled GeoTIFF
MAX_PICTURE_PX = 64 << 20
#: one block (a TIFF tile or strip, a VRT band's block) GDAL decodes at once:
#: GDAL's block cache while ground images are read (geotiff.GDAL_CACHE_MB)
MAX_BLOCK_BYTES = 64 << 20
#: a georeferenced raster's side (2,097,152 px: 2,000 km at 1 m/px, 100 km at 5 cm)
MAX_RASTER_SIDE_PX = 1 << 21
#: one VRT file, the VRTs nested in one another, the sources of all of them
MAX_VRT_BYTES = 16 << 20
MAX_VRT_DEPTH = 4
MAX_VRT_SOURCES = 50_000
#: XML nesting inside a VRT (GDAL's own files use 5)
MAX_XML_DEPTH = 16
#: entries of a folder listed to find the files GDAL opens beside a raster
MAX_FOLDER_ENTRIES = 100_000
#: folders ``ground.image_folders`` may list
MAX_IMAGE_FOLDERS = 16
#: folders never allowed as image folders (the root; the system's own)
SYSTEM_FOLDERS = ("/", "/proc", "/sys", "/dev", "/etc", "/run", "/boot")

#: the settings every GDAL read of a ground image runs under
GDAL_OPTIONS = {
    # /vsicurl/, http(s) and the cloud file systems consider only names ending so
    # (none does) to exist: no request is ever sent
    "CPL_VSIL_CURL_ALLOWED_EXTENSIONS": ".cosim-no-network",
    "GDAL_HTTP_MAX_RETRY": "0",
    # .aux.xml side files are not read (an OVERVIEW_FILE there may name any path)
    "GDAL_PAM_ENABLED": "NO",
    # VRT pixel functions in Python, and raw bands (a byte range of any file)
    "GDAL_VRT_ENABLE_PYTHON": "NO",
    "GDAL_VRT_ENABLE_RAWRASTERBAND": "NO",
}


def folders(scenario_dir: str | Path, listed: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The allowed folders: ``scenario_dir`` and ``listed`` (already checked),
    resolved (symbolic links followed)."""
    return tuple(dict.fromkeys(os.path.realpath(f) for f in (str(scenario_dir), *listed)))


def check_folder(path: str) -> str | None:
    """Why ``path`` cannot be an image folder (None: it can)."""
    real = os.path.realpath(path)
    if not os.path.isdir(real):
        return f"{path}: no such folder"
    for s in SYSTEM_FOLDERS:
        if real == s or (s != "/" and real.startswith(s + "/")):
            return f"{path}: {real} is a system folder; name the folder that holds the imagery"
    return None


# --- names and places ---------------------------------------------------------------

def _bad_name(name: str) -> str | None:
    """Why GDAL would not read ``name`` as a plain local file name (None: it would)."""
    if not name:
        return "an empty name"
    low = name.lower()
    if low.startswith("/vsi") or "://" in name:
        return "a network or GDAL virtual path (/vsi..., URL)"
    if ":" in name:
        return "a colon (GDAL reads NAME: as a driver prefix or a URL scheme)"
    if any(c in name for c in "<>\\") or any(ord(c) < 32 or ord(c) == 127 for c in name):
        return "a character GDAL would read as inline XML or a Windows path (<, >, \\) or a " \
               "control character"
    if name != name.strip():
        return "spaces at its start or end"
    if len(name) > 4096:
        return "a name longer than 4096 characters"
    return None


def _inside(real: str, roots: tuple[str, ...]) -> bool:
    return any(real == r or real.startswith(r.rstrip("/") + "/") for r in roots)


def _where(roots: tuple[str, ...]) -> str:
    return ", ".join(roots) + " (more with ground.image_folders)"


def local_file(name: str, roots: tuple[str, ...], what: str = "") -> str:
    """``name`` resolved (symbolic links followed) if it is a regular file inside
    ``roots``; else ImageRefused saying why (``what`` says where it was named)."""
    at = f"{what}: " if what else ""
    why = _bad_name(name)
    if why is not None:
        raise ImageRefused(f"{at}{name[:300]!r} is {why}; a ground image and its sources must "
                           f"be local files inside {_where(roots)}")
    real = os.path.realpath(name)
    try:
        st = os.stat(real)
    except OSError as e:
        raise ImageRefused(f"{at}{name}: no such file ({e.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise ImageRefused(f"{at}{name} is not a regular file (a device, FIFO, socket or "
                           f"folder): it is never opened")
    if not _inside(real, roots):
        shown = name if real == name else f"{name} (-> {real})"
        raise ImageRefused(f"{at}{shown} is outside the allowed folders: {_where(roots)}")
    return real


def _check_block(shown: str, h: Header) -> None:
    if h.block_bytes > MAX_BLOCK_BYTES:
        raise ImageRefused(
            f"{shown}: a block of {h.block_bytes / 2**20:.0f} MB (a tile or strip decoded at "
            f"once) is more than {MAX_BLOCK_BYTES >> 20} MB; tile it, e.g. gdal_translate -co "
            f"TILED=YES -co COMPRESS=DEFLATE IN OUT.tif (or -of COG)")


def _check_picture_size(shown: str, h: Header) -> None:
    if h.pixels > MAX_PICTURE_PX:
        raise ImageRefused(
            f"{shown}: {h.width_px} x {h.height_px} px ({h.pixels / 2**20:.0f} Mpx) is more than "
            f"{MAX_PICTURE_PX >> 20} Mpx decoded whole (it would take "
            f"{h.pixels * 4 * 4 / 3 / 2**30:.1f} GB in every render worker); make it a tiled "
            f"GeoTIFF with overviews, read by windows: gdal_translate -of COG -a_srs EPSG:... "
            f"-a_ullr ... IN OUT.tif")


# --- side files -------------------------------------------------------------------------

@dataclass
class _Walk:
    """What a check has seen: the allowed folders, the files checked, the sources
    counted, and each folder's entries that must not be opened."""

    roots: tuple[str, ...]
    checked: set[str] = field(default_factory=set)
    sources: int = 0
    bad_entries: dict[str, list[tuple[str, str]]] = field(default_factory=dict)


def _bad_entries(walk: _Walk, folder: str) -> list[tuple[str, str]]:
    """(name, why) of the entries of ``folder`` that are not regular files inside
    the allowed folders (listed once per folder)."""
    got = walk.bad_entries.get(folder)
    if got is not None:
        return got
    got = []
    try:
        with os.scandir(folder or ".") as it:
            for k, e in enumerate(it):
                if k >= MAX_FOLDER_ENTRIES:
                    raise ImageRefused(f"{folder}: more than {MAX_FOLDER_ENTRIES} entries")
                try:
                    if e.is_file(follow_symlinks=False):
                        continue
                    if e.is_symlink():
                        real = os.path.realpath(e.path)
                        if _inside(real, walk.roots) and (os.path.isfile(real)
                                                          or os.path.isdir(real)):
                            continue
                        got.append((e.name, f"a link to {real}"))
                    elif not e.is_dir(follow_symlinks=False):
                        got.append((e.name, "not a regular file"))
                except OSError:
                    got.append((e.name, "not readable"))
    except OSError as e:
        raise ImageRefused(f"{folder}: cannot list it: {e.strerror or e}") from None
    walk.bad_entries[folder] = got
    return got


def _check_side_files(walk: _Walk, name: str) -> None:
    """GDAL opens files beside a raster named after it (NAME.ovr, NAME.msk,
    STEM.tfw, STEM.aux, STEM_RPC.TXT, ...): none may be a link out of the
    allowed folders or a device, FIFO or socket; external overviews and masks
    must be TIFFs whose blocks are within the limit."""
    folder, base = os.path.split(name)
    if not _inside(os.path.realpath(folder or "."), walk.roots):
        raise ImageRefused(f"{name} is named in {folder}, outside the allowed folders, where "
                           f"GDAL looks for files beside it: {_where(walk.roots)}")
    stem = os.path.splitext(base)[0].lower()
    for entry, why in _bad_entries(walk, folder):
        low = entry.lower()
        if low != base.lower() and (low.startswith(stem + ".") or low.startswith(stem + "_")):
            raise ImageRefused(f"{os.path.join(folder, entry)} ({why}) lies beside {name}, and "
                               f"GDAL would open it with it; remove it or move the image")
    for ext in (".ovr", ".msk", ".OVR", ".MSK"):
        side = name + ext
        if os.path.isfile(side):
            real = local_file(side, walk.roots)
            _check_block(side, header(real, side, "tiff"))


# --- VRT ----------------------------------------------------------------------------------

@dataclass
class _Node:
    tag: str  # lower case: GDAL compares names without case
    attrs: dict[str, str]  # names lower case
    line: int
    children: list[_Node] = field(default_factory=list)
    text: list[str] = field(default_factory=list)
    commented: bool = False  # a comment inside (GDAL's value is the text before it)


class _XmlRefused(Exception):
    def __init__(self, line: int, why: str) -> None:
        super().__init__(line, why)
        self.line, self.why = line, why


def _parse_xml(data: bytes) -> _Node:
    """The element tree of a VRT (expat; no DTD, entity declarations, CDATA or
    processing instructions, at most ``MAX_XML_DEPTH`` deep)."""
    import pyexpat

    try:
        data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise _XmlRefused(data[:e.start].count(b"\n") + 1, "not UTF-8 text") from None
    p = pyexpat.ParserCreate(encoding="utf-8")
    stack: list[_Node] = []
    roots: list[_Node] = []

    def refuse(why: str) -> Any:
        def handler(*_: Any) -> None:
            raise _XmlRefused(p.CurrentLineNumber, why)
        return handler

    def start(tag: str, attrs: dict[str, str]) -> None:
        if len(stack) >= MAX_XML_DEPTH:
            raise _XmlRefused(p.CurrentLineNumber, f"elements nested over {MAX_XML_DEPTH} deep")
        low = {k.lower(): v for k, v in attrs.items()}
        if len(low) != len(attrs):
            raise _XmlRefused(p.CurrentLineNumber, f"<{tag}> names an attribute twice (GDAL "
                                                   "compares names without case)")
        node = _Node(tag.lower(), low, p.CurrentLineNumber)
        (stack[-1].children if stack else roots).append(node)
        stack.append(node)

    def end(_: str) -> None:
        stack.pop()

    def text(s: str) -> None:
        if stack:
            stack[-1].text.append(s)

    def comment(_: str) -> None:
        if stack:
            stack[-1].commented = True

    p.StartElementHandler, p.EndElementHandler = start, end
    p.CharacterDataHandler, p.CommentHandler = text, comment
    p.StartDoctypeDeclHandler = refuse("a DOCTYPE (document type declaration)")
    p.EntityDeclHandler = refuse("an entity declaration")
    p.ProcessingInstructionHandler = refuse("a processing instruction")
    p.StartCdataSectionHandler = refuse("a CDATA section")
    p.ExternalEntityRefHandler = refuse("an external entity")
    try:
        p.Parse(data, True)
    except pyexpat.ExpatError as e:
        raise _XmlRefused(e.lineno, f"not well-formed XML ({pyexpat.ErrorString(e.code)})") \
            from None
    if len(roots) != 1:
        raise _XmlRefused(1, "not one XML document")
    return roots[0]


#: the elements of a plain VRT mosaic (lower case)
_ELEMENTS = {t.lower() for t in (
    "VRTDataset", "SRS", "GeoTransform", "GCPList", "GCP", "Metadata", "MDI", "VRTRasterBand",
    "MaskBand", "ColorInterp", "NoDataValue", "HideNoDataValue", "Description", "UnitType",
    "Offset", "Scale", "ColorTable", "Entry", "CategoryNames", "Category", "OverviewList",
    "Overview", "SimpleSource", "ComplexSource", "AveragedSource", "NoDataFromMaskSource",
    "SourceFilename", "SourceBand", "SourceProperties", "SrcRect", "DstRect", "ScaleOffset",
    "ScaleRatio", "NODATA", "UseMaskBand", "LUT", "ColorTableComponent", "Exponent", "SrcMin",
    "SrcMax", "DstMin", "DstMax", "MaskValueThreshold", "RemappedValue")}
#: their attributes (lower case); GDAL reads an attribute where it reads a child
#: element of the same name, so no other name is accepted
_ATTRIBUTES = {a.lower() for a in (
    "rasterXSize", "rasterYSize", "dataType", "band", "blockXSize", "blockYSize",
    "relativeToVRT", "shared", "xOff", "yOff", "xSize", "ySize", "resampling", "key", "domain",
    "c1", "c2", "c3", "c4", "Id", "Info", "Pixel", "Line", "X", "Y", "Z", "Projection",
    "dataAxisToSRSAxisMapping", "coordinateEpoch", "subClass")}
#: elements refused with a reason of their own
_REFUSED = {
    "pixelfunctiontype": "a derived band (pixel function)",
    "pixelfunctionlanguage": "a pixel function in another language (Python)",
    "pixelfunctioncode": "pixel function code",
    "pixelfunctionarguments": "a derived band (pixel function)",
    "kernelfilteredsource": "a kernel-filtered source",
    "openoptions": "open options for a source",
    "gdalwarpoptions": "a warped dataset",
    "sourcedataset": "a warped dataset",
    "panchroband": "a pansharpened dataset",
    "input": "a processed dataset",
    "processingsteps": "a processed dataset",
    "imageoffset": "a raw band",
}
_DATA_BYTES = {"byte": 1, "int8": 1, "uint16": 2, "int16": 2, "uint32": 4, "int32": 4,
               "uint64": 8, "int64": 8, "float16": 2, "float32": 4, "float64": 8, "cint16": 4,
               "cint32": 8, "cfloat16": 4, "cfloat32": 8, "cfloat64": 16}


def _int(node: _Node, attr: str, lo: int, hi: int, default: int | None = None) -> int:
    v = node.attrs.get(attr)
    if v is None:
        if default is None:
            raise _XmlRefused(node.line, f"<{node.tag}> needs {attr}")
        return default
    if not re.fullmatch(r"\d{1,10}", v) or not lo <= int(v) <= hi:
        raise _XmlRefused(node.line, f"{attr}={v[:40]!r}: expected a whole number from {lo} "
                                     f"to {hi}")
    return int(v)


def _walk_vrt(walk: _Walk, name: str, real: str, depth: int, chain: tuple[str, ...]) -> None:
    """Check the VRT at ``name`` (resolved ``real``) and everything it names."""
    size = os.path.getsize(real)
    if size > MAX_VRT_BYTES:
        raise ImageRefused(f"{name}: a VRT of {size / 2**20:.1f} MB (at most "
                           f"{MAX_VRT_BYTES >> 20} MB)")
    with open(real, "rb") as f:
        data = f.read(MAX_VRT_BYTES + 1)
    try:
        root = _parse_xml(data)
        if root.tag != "vrtdataset":
            raise _XmlRefused(root.line, f"<{root.tag}>: a VRT is a <VRTDataset>")
        _int(root, "rasterxsize", 1, MAX_RASTER_SIDE_PX)
        _int(root, "rasterysize", 1, MAX_RASTER_SIDE_PX)
        folder = os.path.dirname(name)
        todo = [root]
        while todo:
            node = todo.pop()
            todo.extend(reversed(node.children))  # in document order
            _check_element(node)
            if node.tag == "sourcefilename":
                _check_source(walk, node, folder, depth, chain + (real,))
    except _XmlRefused as e:
        raise ImageRefused(f"{name}:{e.line}: {e.why}") from None


def _check_element(node: _Node) -> None:
    why = _REFUSED.get(node.tag)
    if why is not None:
        raise _XmlRefused(node.line, f"<{node.tag}>: {why} is not read; a ground image's VRT "
                                     "may only mosaic files (plain bands and their sources)")
    if node.tag not in _ELEMENTS:
        raise _XmlRefused(node.line, f"<{node.tag}> is not an element of a plain VRT mosaic "
                                     "(bands and their sources)")
    for a in node.attrs:
        if a not in _ATTRIBUTES:
            raise _XmlRefused(node.line, f"<{node.tag} {a}=...>: not an attribute of a plain "
                                         "VRT mosaic")
    sub = node.attrs.get("subclass")
    if sub is not None and not (node.tag == "vrtrasterband"
                                and sub.lower() == "vrtsourcedrasterband"):
        raise _XmlRefused(node.line, f"subClass={sub[:60]!r}: derived, raw, warped, "
                                     "pansharpened and processed VRTs are not read")
    if node.tag == "metadata" and node.attrs.get("format") is not None:
        raise _XmlRefused(node.line, "metadata in another format")
    if node.tag == "vrtrasterband":
        dt = node.attrs.get("datatype", "Byte").lower()
        if dt not in _DATA_BYTES:
            raise _XmlRefused(node.line, f"dataType={dt[:40]!r} is not a GDAL data type")
        bx = _int(node, "blockxsize", 1, MAX_RASTER_SIDE_PX, 128)
        by = _int(node, "blockysize", 1, MAX_RASTER_SIDE_PX, 128)
        if bx * by * _DATA_BYTES[dt] > MAX_BLOCK_BYTES:
            raise _XmlRefused(node.line, f"a block of {bx} x {by} px is more than "
                                         f"{MAX_BLOCK_BYTES >> 20} MB")


def _check_source(walk: _Walk, node: _Node, folder: str, depth: int,
                  chain: tuple[str, ...]) -> None:
    if node.children or node.commented:
        raise _XmlRefused(node.line, "<SourceFilename> holds more than its name")
    text = "".join(node.text)
    rel = node.attrs.get("relativetovrt", "0")
    if rel not in ("0", "1"):
        raise _XmlRefused(node.line, f"relativeToVRT={rel[:20]!r}: expected 0 or 1")
    walk.sources += 1
    if walk.sources > MAX_VRT_SOURCES:
        raise _XmlRefused(node.line, f"more than {MAX_VRT_SOURCES} sources in all")
    try:
        if _bad_name(text) is None and not text.startswith("/"):
            if rel == "0":
                raise ImageRefused(f"{text!r} with relativeToVRT=\"0\" is relative to the "
                                   "working directory; give relativeToVRT=\"1\"")
            text = os.path.join(folder, text) if folder else text
        real = local_file(text, walk.roots, "source")
        if real in chain:
            raise ImageRefused(f"source {text} is a VRT that names itself")
        if real in walk.checked:
            return
        walk.checked.add(real)
        h = header(real, text)
        if h.kind == "vrt":
            if depth >= MAX_VRT_DEPTH:
                raise ImageRefused(f"source {text}: VRTs nested more than {MAX_VRT_DEPTH} deep")
            _walk_vrt(walk, text, real, depth + 1, chain)
        else:
            if h.kind in ("png", "jpeg"):  # GDAL may decode them whole
                _check_picture_size(text, h)
            _check_block(text, h)
            _check_sides(text, h)
        _check_side_files(walk, text)
    except ImageRefused as e:
        raise _XmlRefused(node.line, str(e)) from None


def _check_sides(shown: str, h: Header) -> None:
    if max(h.width_px, h.height_px) > MAX_RASTER_SIDE_PX:
        raise ImageRefused(f"{shown}: {h.width_px} x {h.height_px} px: at most "
                           f"{MAX_RASTER_SIDE_PX} px a side")


# --- the checks ---------------------------------------------------------------------------

def check_picture(name: str, roots: tuple[str, ...]) -> str:
    """A picture decoded whole (PNG, JPEG, TIFF placed by origin and m_per_px):
    its resolved path, or ImageRefused."""
    walk = _Walk(roots)
    real = local_file(name, roots)
    h = header(real, name)
    if h.kind == "vrt":
        raise ImageRefused(f"{name}: a VRT is read by GDAL, placed by its own georeference; a "
                           "picture must be PNG, JPEG or TIFF")
    _check_picture_size(name, h)
    _check_block(name, h)
    _check_side_files(walk, real)  # GDAL looks at it too (is it a GeoTIFF placed by hand?)
    return real


def check_georeferenced(name: str, roots: tuple[str, ...]) -> str:
    """A GeoTIFF or VRT read by GDAL, with everything it names: its resolved
    path, or ImageRefused."""
    walk = _Walk(roots)
    real = local_file(name, roots)
    walk.checked.add(real)
    h = header(real, name)
    if h.kind == "vrt":  # GDAL is given the resolved path: its sources are relative to it
        _walk_vrt(walk, real, real, 1, ())
    elif h.kind == "tiff":
        _check_block(name, h)
        _check_sides(name, h)
    else:
        raise ImageRefused(f"{name}: a georeferenced image must be a GeoTIFF or a VRT")
    _check_side_files(walk, real)
    return real


def gdal_driver(path: str) -> str:
    """The one GDAL driver that may open the file at ``path``: 'GTiff' or 'VRT'
    (by its content); ImageRefused for anything else."""
    try:
        with open(path, "rb") as f:
            kind = sniff(f.read(1024))
    except OSError as e:
        raise ImageRefused(f"{path}: cannot read it: {e.strerror or e}") from None
    if kind == "tiff":
        return "GTiff"
    if kind == "vrt":
        return "VRT"
    raise ImageRefused(f"{path}: not a TIFF or a VRT")
