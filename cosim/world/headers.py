"""Raster file headers, read without decoding anything: a file's kind from its
first kilobyte (as GDAL picks a driver: by content, not by name), a PNG's
IHDR, a JPEG's frame header, a TIFF's (or BigTIFF's) directories with the
largest block any of them makes a reader decode at once. Every offset and
count is checked against the file and bounded (``MAX_TIFF_IFDS``,
``MAX_TIFF_ENTRIES``, ``MAX_JPEG_SEGMENTS``): a hostile header is an
``ImageRefused`` saying what is wrong, never a long read or a large
allocation. cosim.renderer.imagery decides what the sizes may be.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from typing import IO

#: a TIFF's directories (the image, its overviews and masks) and the entries of one
MAX_TIFF_IFDS = 64
MAX_TIFF_ENTRIES = 4096
#: segments read in a JPEG before its frame header
MAX_JPEG_SEGMENTS = 4096
#: the kinds a ground image and a VRT's sources may be, by their names' endings
SUFFIXES = {".tif": "tiff", ".tiff": "tiff", ".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg",
            ".vrt": "vrt"}
_KIND_NAMES = {"tiff": "a TIFF", "png": "a PNG", "jpeg": "a JPEG", "vrt": "a VRT"}
#: text in a file's first kilobyte that makes GDAL read it as a dataset description
_XML_DATASETS = (b"<vrtdataset", b"<gdaltileindexdataset", b"<gdal_wms", b"<gdal_wmts",
                 b"<wcs_gdal", b"<gdal_wcs")


class ImageRefused(ValueError):
    """A ground image, or a file it names, that is not read (the message says
    which file, where and why)."""


@dataclass(frozen=True)
class Header:
    """What a raster file declares: its kind, its size and the largest block a
    reader decodes at once (bytes; a PNG or JPEG: the whole image)."""

    kind: str
    width_px: int
    height_px: int
    block_bytes: int

    @property
    def pixels(self) -> int:
        return self.width_px * self.height_px


def sniff(head: bytes) -> str | None:
    """The kind of a file from its first kilobyte: 'vrt' (GDAL reads any file
    with ``<VRTDataset`` there as one), 'tiff', 'png', 'jpeg', 'xml' (another
    dataset description GDAL reads) or None."""
    low = head[:1024].lower()
    if b"<vrtdataset" in low:
        return "vrt"
    if any(m in low for m in _XML_DATASETS):
        return "xml"
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "tiff"
    if head[:8] == b"\x89PNG\r\n\x1a\n":
        return "png"
    if head[:3] == b"\xff\xd8\xff":
        return "jpeg"
    return None


def _read_at(f: IO[bytes], offset: int, n: int, size: int, what: str) -> bytes:
    if offset < 0 or offset + n > size:
        raise ImageRefused(f"{what} lies beyond the end of the file (cut short?)")
    f.seek(offset)
    data = f.read(n)
    if len(data) != n:
        raise ImageRefused(f"{what} lies beyond the end of the file (cut short?)")
    return data


_TIFF_SIZES = {1: 1, 2: 1, 3: 2, 4: 4, 6: 1, 7: 1, 8: 2, 9: 4, 16: 8, 17: 8, 18: 8}
_TIFF_INTS = {1: "B", 3: "H", 4: "I", 6: "b", 8: "h", 9: "i", 16: "Q", 17: "q", 18: "Q"}


def _tiff(f: IO[bytes], size: int) -> Header:
    """A TIFF's (or BigTIFF's) first image and the largest block of any of its
    directories (overviews and masks follow the image)."""
    head = _read_at(f, 0, 16 if size >= 16 else 8, size, "the TIFF header")
    bo = "<" if head[:2] == b"II" else ">"
    big = struct.unpack(bo + "H", head[2:4])[0] == 43
    if big:
        if len(head) < 16 or struct.unpack(bo + "HH", head[4:8]) != (8, 0):
            raise ImageRefused("a BigTIFF header that is not one")
        offset = struct.unpack(bo + "Q", head[8:16])[0]
    else:
        offset = struct.unpack(bo + "I", head[4:8])[0]
    count_fmt, entry_fmt, entry_n, next_fmt = (("Q", "HHQ", 20, "Q") if big
                                               else ("H", "HHI", 12, "I"))
    inline = 8 if big else 4
    seen: set[int] = set()
    first: tuple[int, int] | None = None
    largest = 0
    for k in range(MAX_TIFF_IFDS + 1):
        if offset == 0:
            break
        if k == MAX_TIFF_IFDS:
            raise ImageRefused(f"more than {MAX_TIFF_IFDS} TIFF directories")
        if offset in seen:
            raise ImageRefused("its TIFF directories form a loop")
        seen.add(offset)
        cn = struct.calcsize(count_fmt)
        n = struct.unpack(bo + count_fmt, _read_at(f, offset, cn, size, "a TIFF directory"))[0]
        if n > MAX_TIFF_ENTRIES:
            raise ImageRefused(f"a TIFF directory of {n} entries (at most {MAX_TIFF_ENTRIES})")
        raw = _read_at(f, offset + cn, n * entry_n + struct.calcsize(next_fmt), size,
                       "a TIFF directory")
        tags: dict[int, list[int]] = {}
        for i in range(n):
            e = raw[i * entry_n:(i + 1) * entry_n]
            tag, typ, cnt = struct.unpack(bo + entry_fmt, e[:4 + struct.calcsize(entry_fmt[2])])
            if tag not in (256, 257, 258, 259, 273, 277, 278, 284, 322, 323) \
                    or typ not in _TIFF_INTS:
                continue
            if cnt > 65536:
                raise ImageRefused(f"TIFF tag {tag} with {cnt} values")
            width = _TIFF_SIZES[typ] * cnt
            value = e[4 + struct.calcsize(entry_fmt[2]):]
            if tag == 273:  # StripOffsets: only how many
                tags[tag] = [cnt]
                continue
            if width > inline:
                if cnt > 1024:
                    raise ImageRefused(f"TIFF tag {tag} with {cnt} values")
                where = struct.unpack(bo + next_fmt, value[:struct.calcsize(next_fmt)])[0]
                value = _read_at(f, where, width, size, f"TIFF tag {tag}'s values")
            tags[tag] = list(struct.unpack(f"{bo}{cnt}{_TIFF_INTS[typ]}", value[:width]))
        offset = struct.unpack(bo + next_fmt, raw[n * entry_n:])[0]
        w, h = (tags.get(256) or [0])[0], (tags.get(257) or [0])[0]
        if w <= 0 or h <= 0:
            raise ImageRefused("a TIFF image without a width and a height")
        spp = max(1, (tags.get(277) or [1])[0])
        bits = max(tags.get(258) or [8]) or 8
        planar = (tags.get(284) or [1])[0] == 2
        if 322 in tags and 323 in tags:
            bw, bh = tags[322][0], tags[323][0]
        else:
            bw, bh = w, min(h, (tags.get(278) or [h])[0] or h)
            if (tags.get(259) or [1])[0] == 1 and (tags.get(273) or [1])[0] <= 1:
                bh = 1  # one uncompressed strip: GDAL reads it row by row
        block = -(-bw * bh * bits * (1 if planar else spp) // 8)
        largest = max(largest, block)
        if first is None:
            first = (w, h)
    if first is None:
        raise ImageRefused("a TIFF without an image")
    return Header("tiff", first[0], first[1], largest)


def _png(f: IO[bytes], size: int) -> Header:
    d = _read_at(f, 8, 18, size, "the PNG header")  # length, IHDR, width, height, depth, colour
    if d[4:8] != b"IHDR":
        raise ImageRefused("a PNG whose first chunk is not its header (IHDR)")
    w, h, depth, colour = struct.unpack(">IIBB", d[8:18])
    if w <= 0 or h <= 0:
        raise ImageRefused("a PNG without a width and a height")
    channels = {0: 1, 2: 3, 3: 4, 4: 2, 6: 4}.get(colour, 4)
    return Header("png", w, h, w * h * channels * max(1, depth // 8))


_SOF = set(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def _jpeg(f: IO[bytes], size: int) -> Header:
    pos = 2
    for _ in range(MAX_JPEG_SEGMENTS):
        m = _read_at(f, pos, 2, size, "a JPEG segment")
        if m[0] != 0xFF:
            raise ImageRefused("a JPEG whose segments do not follow one another")
        if m[1] == 0xFF:  # fill byte
            pos += 1
            continue
        marker = m[1]
        if marker in (0x01, *range(0xD0, 0xD8)):
            pos += 2
            continue
        if marker in (0xD9, 0xDA):
            raise ImageRefused("a JPEG without a frame header before its data")
        length = struct.unpack(">H", _read_at(f, pos + 2, 2, size, "a JPEG segment"))[0]
        if length < 2:
            raise ImageRefused("a JPEG segment of a length below 2")
        if marker in _SOF:
            d = _read_at(f, pos + 4, 6, size, "the JPEG frame header")
            h, w, comps = struct.unpack(">HHB", d[1:6])
            if w <= 0 or h <= 0:
                raise ImageRefused("a JPEG without a width and a height")
            return Header("jpeg", w, h, w * h * max(1, comps) * 2)
        pos += 2 + length
    raise ImageRefused(f"a JPEG without a frame header in its first {MAX_JPEG_SEGMENTS} segments")


def header(real: str, name: str | None = None, want: str | None = None) -> Header:
    """The header of the regular file ``real`` (already checked by ``local_file``);
    its kind must be ``want``, by default what its name's ending says (``name``,
    default ``real``). ImageRefused says which file and why."""
    shown = name or real
    want = want or SUFFIXES.get(os.path.splitext(shown)[1].lower())
    if want is None:
        raise ImageRefused(f"{shown}: a ground image and its sources must be TIFF (.tif), PNG, "
                           f"JPEG or VRT files (by their names' endings: {', '.join(SUFFIXES)})")
    try:
        with open(real, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            kind = sniff(f.read(1024))
            if kind != want:
                got = "an XML dataset description" if kind == "xml" else \
                    _KIND_NAMES.get(kind or "", "none of TIFF, PNG, JPEG or VRT")
                raise ImageRefused(f"{shown}: its name says {_KIND_NAMES[want]} but its content "
                                   f"is {got} (GDAL goes by the content)")
            if kind == "vrt":
                return Header("vrt", 0, 0, 0)  # the VRT walk reads its sizes
            read = {"tiff": _tiff, "png": _png, "jpeg": _jpeg}[kind]
            try:
                return read(f, size)
            except (struct.error, ValueError) as e:
                raise ImageRefused(f"{shown}: cannot read it as a raster image: {e}") from None
    except OSError as e:
        raise ImageRefused(f"{shown}: cannot read it: {e.strerror or e}") from None


