"""Hostile ground imagery: what a ground image and the files it names may be.
Every case goes through ``cosim validate`` (exit 2, a ``file:line`` message
naming the file and why) with small generated files: VRTs naming a URL
(a loopback server must see no request), /etc/passwd, a file outside the
scenario's folder, a nested VRT that escapes, pixel functions, DTDs; a PNG
and a TIFF declaring sizes no render worker can afford (headers only). A
plain mosaic inside the folder (or in a folder the scenario allows) passes."""

from __future__ import annotations

import os
import re
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine

from cosim.cli import main
from cosim.core.geo import LocalFrame
from cosim.errors import ConfigError
from cosim.renderer.ground import GroundTexture
from cosim.world.ground import GroundSpec
from tests.renderer.test_fuzz_rasters import Traps, _tiff_entries
from tests.renderer.test_geotiff import SCENARIO

LAT0, LON0 = 37.0, -122.0
GROUND_LINE = SCENARIO.count("\n") + 1  # the line of `ground:`, appended last


def geotiff(path: Path, side: int = 64) -> Path:
    """A small georeferenced GeoTIFF (UTM zone 10) near the origin."""
    rgb = np.full((3, side, side), 90, np.uint8)
    with rasterio.open(path, "w", driver="GTiff", width=side, height=side, count=3,
                       dtype="uint8", crs="EPSG:32610",
                       transform=Affine(1.0, 0.0, 588000.0, 0.0, -1.0, 4096000.0)) as ds:
        ds.write(rgb)
    return path


def vrt(path: Path, *sources: tuple[str, str], extra: str = "", side: int = 64) -> Path:
    """A VRT mosaic of ``sources`` ((file name, relativeToVRT), band 1 each)."""
    body = "".join(f"""
        <SimpleSource><SourceFilename relativeToVRT="{rel}">{name}</SourceFilename>
          <SourceBand>1</SourceBand></SimpleSource>""" for name, rel in sources)
    path.write_text(f"""<VRTDataset rasterXSize="{side}" rasterYSize="{side}">
  <SRS>EPSG:32610</SRS>
  <GeoTransform>588000.0, 1.0, 0.0, 4096000.0, 0.0, -1.0</GeoTransform>
  <VRTRasterBand dataType="Byte" band="1">{extra}{body}
  </VRTRasterBand>
</VRTDataset>
""")
    return path


def png_header(path: Path, width: int, height: int) -> Path:
    """A PNG's signature and header chunk only: it declares width x height RGB."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = struct.pack(">I", len(ihdr)) + b"IHDR" + ihdr + \
        struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk)
    return path


def tiff_header(path: Path, width: int, height: int, rows_per_strip: int,
                compression: int = 8) -> Path:
    """A TIFF directory only: width x height RGB in strips of ``rows_per_strip``
    (deflate), georeferenced by nothing (the block is refused first)."""
    entries = [(256, 4, 1, width), (257, 4, 1, height), (258, 3, 1, 8), (259, 3, 1, compression),
               (262, 3, 1, 2), (273, 4, 1, 0), (277, 3, 1, 3), (278, 4, 1, rows_per_strip),
               (279, 4, 1, 0)]
    ifd = struct.pack("<H", len(entries)) + b"".join(
        struct.pack("<HHII", *e) for e in entries) + struct.pack("<I", 0)
    path.write_bytes(b"II*\x00" + struct.pack("<I", 8) + ifd)
    return path


def validate(scn: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    rc = main(["validate", str(scn)])
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return rc, out.err


def scenario(folder: Path, ground: str) -> Path:
    p = folder / "s.yaml"
    p.write_text(SCENARIO + ground + "\n")
    return p


def refused(folder: Path, ground: str, capsys: pytest.CaptureFixture[str], *why: str) -> str:
    """``cosim validate`` of the scenario with ``ground`` exits 2 with a message
    at the ground's line naming each of ``why`` (regular expressions)."""
    rc, err = validate(scenario(folder, ground), capsys)
    assert rc == 2, err
    assert re.search(rf"s\.yaml:{GROUND_LINE}: ground(\.[\w\[\]]+)?: ", err), err
    for w in why:
        assert re.search(w, err), (w, err)
    return err


@pytest.fixture
def server() -> Iterator[tuple[int, list[str]]]:
    """A loopback HTTP server on an ephemeral port and the requests it saw."""
    traps = Traps([])
    try:
        yield traps.port, traps.requests
    finally:
        traps.close()


@pytest.fixture
def site(tmp_path: Path) -> Path:
    """The scenario's folder, beside another folder holding a GeoTIFF."""
    (tmp_path / "site").mkdir()
    (tmp_path / "elsewhere").mkdir()
    geotiff(tmp_path / "elsewhere" / "far.tif")
    geotiff(tmp_path / "site" / "near.tif")
    return tmp_path / "site"


def test_a_plain_mosaic_inside_the_folder_passes(site: Path, capsys) -> None:
    png = site / "tile.png"
    import cv2

    cv2.imwrite(str(png), np.full((64, 64, 3), 120, np.uint8))
    vrt(site / "ok.vrt", ("near.tif", "1"), (str(site / "near.tif"), "0"), ("tile.png", "1"))
    rc, err = validate(scenario(site, "ground: {image: ok.vrt}"), capsys)
    assert rc == 0, err
    # a source in another folder passes once the scenario allows that folder
    vrt(site / "far.vrt", (str(site.parent / "elsewhere" / "far.tif"), "0"))
    rc, err = validate(scenario(site, "ground: {image: far.vrt, image_folders: "
                                      "[../elsewhere]}"), capsys)
    assert rc == 0, err


def test_a_vrt_naming_a_url_is_refused_and_nothing_is_fetched(site: Path, server, capsys) -> None:
    port, seen = server
    for name in (f"/vsicurl/http://127.0.0.1:{port}/a.tif", f"http://127.0.0.1:{port}/b.tif",
                 f"vrt:///vsicurl/http://127.0.0.1:{port}/c.tif"):
        vrt(site / "net.vrt", (name, "0"))
        refused(site, "ground: {image: net.vrt}", capsys, r"net\.vrt:5: ",
                "network or GDAL virtual path")
    assert seen == []  # validation never reached the server
    # nor does a render worker (the same check where the file is opened)
    spec = GroundSpec(kind="image", image=str(site / "net.vrt"), geotiff=True)
    with pytest.raises(ConfigError, match=r"ground\.image: .*net\.vrt:5: .*network"):
        GroundTexture(spec, LocalFrame(LAT0, LON0, 10.0), 1)
    assert seen == []


def test_a_vrt_naming_a_local_file_outside_the_folder_is_refused(site: Path, capsys) -> None:
    vrt(site / "passwd.vrt", ("/etc/passwd", "0"))
    refused(site, "ground: {image: passwd.vrt}", capsys, r"passwd\.vrt:5: ",
            r"/etc/passwd.* is outside the allowed folders")
    vrt(site / "far.vrt", ("../elsewhere/far.tif", "1"))
    refused(site, "ground: {image: far.vrt}", capsys, r"far\.vrt:5: ",
            r"elsewhere/far\.tif.* outside the allowed folders", "ground.image_folders")
    # the same through a link inside the folder
    (site / "link.tif").symlink_to(site.parent / "elsewhere" / "far.tif")
    vrt(site / "link.vrt", ("link.tif", "1"))
    refused(site, "ground: {image: link.vrt}", capsys, r"link\.tif \(-> .*far\.tif\) is outside")
    # and the image itself
    refused(site, "ground: {image: ../elsewhere/far.tif}", capsys, "outside the allowed folders")


def test_a_nested_vrt_that_escapes_is_refused(site: Path, capsys) -> None:
    (site / "sub").mkdir()
    vrt(site / "sub" / "inner.vrt", ("../../elsewhere/far.tif", "1"))
    vrt(site / "outer.vrt", ("sub/inner.vrt", "1"))
    refused(site, "ground: {image: outer.vrt}", capsys,
            r"outer\.vrt:5: .*sub/inner\.vrt:5: source: .*far\.tif.* outside the allowed folders")
    # a VRT naming itself, and one nested too deep
    vrt(site / "self.vrt", ("self.vrt", "1"))
    refused(site, "ground: {image: self.vrt}", capsys, "names itself")
    for k in range(6):
        vrt(site / f"d{k}.vrt", (f"d{k + 1}.vrt", "1"))
    vrt(site / "d6.vrt", ("near.tif", "1"))
    refused(site, "ground: {image: d0.vrt}", capsys, "nested more than 4 deep")


def test_special_files_and_hostile_vrt_xml_are_refused(site: Path, capsys) -> None:
    os.mkfifo(site / "pipe.tif")
    vrt(site / "fifo.vrt", ("pipe.tif", "1"))
    refused(site, "ground: {image: fifo.vrt}", capsys, "not a regular file")
    vrt(site / "dev.vrt", ("/dev/zero", "0"))
    refused(site, "ground: {image: dev.vrt}", capsys, "not a regular file")
    vrt(site / "cwd.vrt", ("near.tif", "0"))
    refused(site, "ground: {image: cwd.vrt}", capsys, "relative to the working directory")
    python = """<PixelFunctionLanguage>Python</PixelFunctionLanguage>
    <PixelFunctionCode>import os; os.system('touch pwned')</PixelFunctionCode>"""
    vrt(site / "py.vrt", ("near.tif", "1"), extra=python)
    refused(site, "ground: {image: py.vrt}", capsys, r"py\.vrt:4: .*Python")
    text = (site / "py.vrt").read_text().replace(
        'band="1">', 'band="1" subClass="VRTDerivedRasterBand">')
    (site / "derived.vrt").write_text(text.replace(python, ""))
    refused(site, "ground: {image: derived.vrt}", capsys, r"derived\.vrt:4: subClass")
    good = vrt(site / "good.vrt", ("near.tif", "1")).read_text()
    (site / "dtd.vrt").write_text('<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n' + good)
    refused(site, "ground: {image: dtd.vrt}", capsys, r"dtd\.vrt:1: a DOCTYPE")
    (site / "attr.vrt").write_text(good.replace(
        "<SimpleSource>", '<SimpleSource SourceFilename="/etc/passwd">'))
    refused(site, "ground: {image: attr.vrt}", capsys, r"attr\.vrt:5: .*sourcefilename=")
    (site / "cdata.vrt").write_text(good.replace(">near.tif<", "><![CDATA[near.tif]]><"))
    refused(site, "ground: {image: cdata.vrt}", capsys, "CDATA")
    # a TIFF holding a VRT: GDAL goes by the content
    (site / "fake.tif").write_text(good)
    refused(site, "ground: {image: fake.tif}", capsys, "its name says a TIFF but its content "
                                                      "is a VRT")


def test_declared_sizes_a_render_worker_cannot_afford_are_refused(site: Path, capsys,
                                                                   tmp_path: Path) -> None:
    big = png_header(site / "huge.png", 30000, 30000)
    assert big.stat().st_size < 100
    place = "m_per_px: 0.5, origin: {north_m: 0, east_m: 0}"
    refused(site, f"ground: {{image: huge.png, {place}}}", capsys,
            r"huge\.png: 30000 x 30000 px \(858 Mpx\) is more than 64 Mpx decoded whole",
            "tiled GeoTIFF")
    # a render worker never decodes it either (a spec made without the scenario)
    spec = GroundSpec(kind="image", image=str(big), m_per_px=0.5, origin_ne_m=(0.0, 0.0))
    with pytest.raises(ConfigError, match=r"ground\.image: .*huge\.png: 30000 x 30000 px"):
        GroundTexture(spec, LocalFrame(LAT0, LON0, 10.0), 1)
    # ... and in a VRT, where GDAL may decode a PNG whole
    vrt(site / "png.vrt", ("huge.png", "1"))
    refused(site, "ground: {image: png.vrt}", capsys, r"huge\.png: 30000 x 30000 px")
    # TIFFs whose one compressed strip is 183 MB (a picture of 61 Mpx) or 2.6 GB
    tiff_header(site / "strip.tif", 8000, 8000, 8000)
    refused(site, f"ground: {{image: strip.tif, {place}}}", capsys,
            r"strip\.tif: a block of 183 MB .* more than 64 MB", "TILED=YES")
    tiff_header(site / "strip.tif", 30000, 30000, 30000)
    refused(site, "ground: {image: strip.tif}", capsys,
            r"strip\.tif: a block of 2575 MB .* more than 64 MB")
    # a VRT declaring a side beyond the limit, or a block too large
    vrt(site / "wide.vrt", ("near.tif", "1"), side=1 << 22)
    refused(site, "ground: {image: wide.vrt}", capsys, r"wide\.vrt:1: rasterxsize='4194304'")
    text = vrt(site / "block.vrt", ("near.tif", "1")).read_text()
    (site / "block.vrt").write_text(text.replace('band="1"', 'band="1" blockXSize="65536" '
                                                             'blockYSize="65536"'))
    refused(site, "ground: {image: block.vrt}", capsys, r"block\.vrt:4: a block of 65536")


def test_files_gdal_opens_beside_a_raster_are_checked(site: Path, capsys) -> None:
    """An external overview that links out of the folder, or is a FIFO, would be
    opened by GDAL with the raster."""
    (site / "near.tif.ovr").symlink_to("/etc/passwd")
    refused(site, "ground: {image: near.tif}", capsys, r"near\.tif\.ovr \(a link to /etc/passwd\)"
                                                       r" lies beside")
    (site / "near.tif.ovr").unlink()
    os.mkfifo(site / "near.tif.msk")
    refused(site, "ground: {image: near.tif}", capsys, r"near\.tif\.msk \(not a regular file\)")
    (site / "near.tif.msk").unlink()
    (site / "tiles").mkdir()  # a link that stays inside is fine, to a folder too
    (site / "near_tiles").symlink_to(site / "tiles")
    rc, err = validate(scenario(site, "ground: {image: near.tif}"), capsys)
    assert rc == 0, err


def test_image_folders_are_checked(site: Path, capsys) -> None:
    refused(site, "ground: {image: near.tif, image_folders: [/etc]}", capsys,
            "is a system folder")
    refused(site, "ground: {image: near.tif, image_folders: [nowhere]}", capsys,
            "no such folder")
    refused(site, "ground: {image: near.tif, image_folders: 3}", capsys, "expected a list")


def test_gdal_reads_with_the_network_and_side_files_off(site: Path, server) -> None:
    """The second line of defence: GDAL itself, under geotiff's settings, sends no
    request for a VRT that names a URL (whatever the checks let through)."""
    from cosim.world import geotiff as gt
    from cosim.world import imagery

    port, seen = server
    vrt(site / "net.vrt", (f"/vsicurl/http://127.0.0.1:{port}/a.tif", "0"))
    assert "cannot read its pixels" in (gt.probe(str(site / "net.vrt")) or "")
    assert seen == []
    assert imagery.GDAL_OPTIONS["GDAL_VRT_ENABLE_PYTHON"] == "NO"


def test_overviews_larger_than_the_image_are_refused(site: Path, capsys) -> None:
    """GDAL gives an overview wider than its image the factor 0 (a division by
    zero when the ground was drawn): found by tests/renderer/test_fuzz_rasters.py."""
    from rasterio.enums import Resampling

    path = geotiff(site / "ovr.tif", side=256)
    with rasterio.open(path, "r+") as ds:
        ds.build_overviews([2], Resampling.average)
    data = bytearray(path.read_bytes())
    widths = [at for tag, _, at in _tiff_entries(bytes(data)) if tag == 256]
    assert len(widths) == 2  # the image's and its overview's
    data[widths[1]:widths[1] + 4] = struct.pack("<I", 4096)
    path.write_bytes(bytes(data))
    refused(site, "ground: {image: ovr.tif}", capsys,
            r"ovr\.tif: its overviews \(factors \[0\]\) are not smaller than the image")


def test_a_picture_whose_pixels_do_not_decode_is_refused(site: Path, capfd) -> None:
    """Validation decodes a picture as the render workers will (its size bounded
    first); OpenCV's own log lines are kept out of the messages."""
    import cv2

    rng = np.random.default_rng(1)
    place = "m_per_px: 0.5, origin: {north_m: 0, east_m: 0}"

    def damaged(name: str) -> str:
        cv2.imwrite(str(site / name), rng.integers(0, 255, (64, 64, 3), np.uint8))
        data = bytearray((site / name).read_bytes())
        n = len(data)  # its header whole, its pixels damaged
        data[n // 4:n // 2] = rng.integers(0, 255, n // 2 - n // 4, np.uint8).tobytes()
        (site / f"bad{name[3:]}").write_bytes(data)
        return f"bad{name[3:]}"

    refused(site, f"ground: {{image: {damaged('pic.png')}, {place}}}", capfd,
            r"cannot read .*bad\.png as an image")
    # a TIFF's decoder gets through with errors: valid, and quiet about them
    rc, err = validate(scenario(site, f"ground: {{image: {damaged('pic.tif')}, {place}}}"),
                       capfd)
    assert rc == 0 and "TIFF_Error" not in err, err
