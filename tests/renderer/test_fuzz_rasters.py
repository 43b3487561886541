"""Raster fuzzing: mutated ground images (GeoTIFFs with overviews, strip
TIFFs, PNGs, VRT mosaics and the sources they name: headers, declared sizes,
truncation, stray bytes, other kinds' content, hostile VRT XML) go through
``cosim validate`` and, where they are valid, a rendered frame over them
(and a few short ``cosim run``s). Each must end with exit 0, or 2 and messages
carrying their file line (a run: 1 naming the camera when the pixels turn out
unreadable); never a traceback, a hang (a watchdog fails a case that takes too
long) or an attempt to read outside the allowed folders: FIFOs there (and one
inside) report any opening, and a loopback HTTP server any request.

Seeded and bounded (``MUTANTS`` cases, about 20 s here); ``COSIM_FUZZ_SCALE=N``
multiplies them.
"""

from __future__ import annotations

import http.server
import os
import random
import re
import struct
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
import rasterio
from affine import Affine
from rasterio.enums import Resampling

from cosim.cli import main
from cosim.core.camera import CameraSpec, camera_pose
from cosim.errors import ConfigError
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import load_scenario
from cosim.world.geotiff import GeoTiffError
from tests.renderer.test_geotiff import SCENARIO
from tests.test_fuzz_scenarios import Hang, check_validate, watchdog

MUTANTS = 160
RUNS = 2  # short `cosim run`s of valid mutants
VALIDATE_LIMIT_S = 20
RENDER_LIMIT_S = 20
RUN_LIMIT_S = 60
LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0
X0, Y0 = 588000.0, 4096000.0  # UTM 10N, about 1.4 km from the origin
CAM = CameraSpec("c", (0,), "nadir", -90.0, False, 60.0, 46.8, 64, 48, 10.0, 12)
PLACE = "m_per_px: 0.5, origin: {north_m: 20, east_m: -20}"


# --- traps ------------------------------------------------------------------------------

pytestmark = pytest.mark.integration  # fuzzing: many renders and runs


class Traps:
    """FIFOs that report being opened (a thread opens each for writing without
    blocking, which succeeds only while a reader has it open, then writes a
    little and closes it so the reader is never stuck), and a loopback HTTP
    server that counts requests."""

    def __init__(self, fifos: list[Path]) -> None:
        self.fifos, self.opened = fifos, list[str]()
        for f in fifos:
            os.mkfifo(f)
        self.requests: list[str] = []
        seen = self.requests

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                seen.append(self.path)
                self.send_response(404)
                self.end_headers()

            do_HEAD = do_GET

            def log_message(self, *a: object) -> None:
                pass

        self.http = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.http.server_address[1]
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self.http.serve_forever, daemon=True),
                         threading.Thread(target=self._watch, daemon=True)]
        for t in self._threads:
            t.start()

    def _watch(self) -> None:
        while not self._stop.is_set():
            for f in self.fifos:
                try:
                    fd = os.open(f, os.O_WRONLY | os.O_NONBLOCK)
                except OSError:  # ENXIO: nobody reads it
                    continue
                self.opened.append(str(f))
                try:
                    os.write(fd, b"II*\x00" + b"\x00" * 60)
                except OSError:
                    pass
                os.close(fd)
            time.sleep(0.002)

    def check(self, what: str) -> None:
        assert not self.opened, f"{what}: opened {self.opened}"
        assert not self.requests, f"{what}: HTTP requests {self.requests}"

    def close(self) -> None:
        self._stop.set()
        self.http.shutdown()
        self.http.server_close()


# --- the corpus -------------------------------------------------------------------------

def _rgb(side: int) -> np.ndarray:
    j, i = np.mgrid[0:side, 0:side]
    out = np.empty((3, side, side), np.uint8)
    out[0], out[1], out[2] = (i * 2) % 256, (j * 2) % 256, 128
    return out


def _geotiff(path: Path, tiled: bool) -> Path:
    kw = dict(tiled=True, blockxsize=64, blockysize=64) if tiled else {}
    with rasterio.open(path, "w", driver="GTiff", width=256, height=256, count=3,
                       dtype="uint8", crs="EPSG:32610", compress="deflate",
                       transform=Affine(0.5, 0.0, X0, 0.0, -0.5, Y0), **kw) as ds:
        ds.write(_rgb(256))
        if tiled:
            ds.build_overviews([2, 4], Resampling.average)
    return path


def _vrt(sources: list[str], side: int = 256) -> str:
    bands = "".join(f"""
  <VRTRasterBand dataType="Byte" band="{b}">
    <ColorInterp>{c}</ColorInterp>""" + "".join(f"""
    <SimpleSource>
      <SourceFilename relativeToVRT="1">{s}</SourceFilename>
      <SourceBand>{b}</SourceBand>
      <SrcRect xOff="0" yOff="0" xSize="64" ySize="64"/>
      <DstRect xOff="{64 * k}" yOff="{64 * k}" xSize="64" ySize="64"/>
    </SimpleSource>""" for k, s in enumerate(sources)) + """
  </VRTRasterBand>""" for b, c in ((1, "Red"), (2, "Green"), (3, "Blue")))
    return f"""<VRTDataset rasterXSize="{side}" rasterYSize="{side}">
  <SRS>EPSG:32610</SRS>
  <GeoTransform>{X0!r}, 0.5, 0.0, {Y0!r}, 0.0, -0.5</GeoTransform>{bands}
</VRTDataset>
"""


def corpus(site: Path) -> dict[str, bytes]:
    """The seeds: a tiled GeoTIFF with overviews, a strip GeoTIFF, a plain TIFF,
    a PNG, a JPEG and a VRT mosaic of some of them (written into ``site``)."""
    _geotiff(site / "cog.tif", tiled=True)
    _geotiff(site / "strip.tif", tiled=False)
    plain = np.moveaxis(_rgb(128), 0, -1)[..., ::-1].copy()
    cv2.imwrite(str(site / "plain.tif"), plain)
    cv2.imwrite(str(site / "pic.png"), plain)
    cv2.imwrite(str(site / "pic.jpg"), plain)
    (site / "mosaic.vrt").write_text(_vrt(["cog.tif", "pic.png", "strip.tif"]))
    return {n: (site / n).read_bytes() for n in ("cog.tif", "strip.tif", "plain.tif",
                                                  "pic.png", "pic.jpg", "mosaic.vrt")}


# --- mutations --------------------------------------------------------------------------

EXTREMES = [0, 1, 7, 65535, 30000, 1 << 20, (1 << 31) - 1, (1 << 32) - 1]


def _tiff_entries(data: bytes) -> list[tuple[int, int, int]]:
    """(tag, type, offset of the value field) of a little-endian TIFF's first
    directories (what rasterio and OpenCV write)."""
    out: list[tuple[int, int, int]] = []
    if data[:4] != b"II*\x00" or len(data) < 8:
        return out
    off = struct.unpack("<I", data[4:8])[0]
    for _ in range(4):
        if not 0 < off < len(data) - 2:
            break
        n = struct.unpack("<H", data[off:off + 2])[0]
        for i in range(min(n, 200)):
            e = off + 2 + 12 * i
            if e + 12 > len(data):
                break
            tag, typ = struct.unpack("<HH", data[e:e + 4])
            out.append((tag, typ, e + 8))
        end = off + 2 + 12 * n
        off = struct.unpack("<I", data[end:end + 4])[0] if end + 4 <= len(data) else 0
    return out


def _tiff_field(rng: random.Random, data: bytes) -> bytes:
    """A size tag (width, height, tile or strip size, samples, bits) set to an
    extreme value."""
    entries = [e for e in _tiff_entries(data) if e[0] in (256, 257, 258, 277, 278, 322, 323)]
    if not entries:
        return _flip(rng, data)
    tag, typ, at = rng.choice(entries)
    v = rng.choice(EXTREMES)
    b = struct.pack("<H", v & 0xFFFF) + b"\0\0" if typ == 3 else struct.pack("<I", v)
    return data[:at] + b + data[at + 4:]


def _png_size(rng: random.Random, data: bytes) -> bytes:
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        return _flip(rng, data)
    w, h = rng.choice(EXTREMES), rng.choice(EXTREMES)
    return data[:16] + struct.pack(">II", w, h) + data[24:]


def _cut(rng: random.Random, data: bytes) -> bytes:
    return data[:rng.randrange(len(data) + 1)]


def _flip(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(rng.choice([1, 2, 8])):
        i = rng.randrange(min(len(b), 512)) if b else 0
        if b:
            b[i] = rng.randrange(256)
    return bytes(b)


def _insert(rng: random.Random, data: bytes) -> bytes:
    at = rng.randrange(len(data) + 1)
    junk = rng.choice([b"<VRTDataset>", b"\x00" * 16, bytes(rng.randrange(256) for _ in range(24)),
                       b"<GDALTileIndexDataset>"])
    return data[:at] + junk + data[at:]


def _other(rng: random.Random, data: bytes, seeds: dict[str, bytes]) -> bytes:
    return rng.choice(list(seeds.values()))


BINARY: list[Callable[..., bytes]] = [_tiff_field, _tiff_field, _png_size, _cut, _cut, _flip,
                                      _flip, _insert]


def hostile_names(site: Path, outside: Path, port: int) -> list[str]:
    return [f"/vsicurl/http://127.0.0.1:{port}/a.tif", f"http://127.0.0.1:{port}/b.tif",
            f"vrt:///vsicurl/http://127.0.0.1:{port}/c.tif", "/etc/passwd", "/dev/zero",
            str(outside / "trap.tif"), "../outside/trap.tif", "trap_link.tif", "pipe.tif",
            "GTIFF_DIR:1:cog.tif", "<VRTDataset><VRTRasterBand/></VRTDataset>",
            "/vsizip/x.zip/a.tif", "mosaic.vrt", "nowhere.tif", "", " cog.tif", "sub/../cog.tif",
            str(site / "cog.tif"), "pic.jpg", "C:\\evil.tif"]


XML_INSERTS = [
    "<PixelFunctionType>sum</PixelFunctionType>",
    "<PixelFunctionLanguage>Python</PixelFunctionLanguage><PixelFunctionCode>"
    "import os; os.system('touch pwned')</PixelFunctionCode>",
    "<OpenOptions><OOI key='GEOREF_SOURCES'>INTERNAL</OOI></OpenOptions>",
    "<KernelFilteredSource><SourceFilename>cog.tif</SourceFilename><Kernel><Size>3</Size>"
    "<Coefs>1 1 1 1 1 1 1 1 1</Coefs></Kernel></KernelFilteredSource>",
    "<Metadata format='xml'><anything/></Metadata>",
    "<Overview><SourceFilename relativeToVRT='1'>cog.tif</SourceFilename>"
    "<SourceBand>1</SourceBand></Overview>",
    "<!-- a comment -->", "<?pi x?>", "<![CDATA[x]]>",
]


def _vrt_text(rng: random.Random, text: str, names: list[str]) -> bytes:
    op = rng.randrange(12)
    if op <= 2:  # a source named otherwise
        name = rng.choice(names)
        rel = rng.choice(["0", "1", "1", "2", ""])
        new = f'<SourceFilename relativeToVRT="{rel}">{name}</SourceFilename>'
        found = list(re.finditer(r"<SourceFilename[^>]*>[^<]*</SourceFilename>", text))
        m = rng.choice(found) if found else None
        if m is not None:
            text = text[:m.start()] + new + text[m.end():]
    elif op == 3:
        m = rng.choice(list(re.finditer(r"</ColorInterp>", text)) or [None])
        if m is not None:
            text = text[:m.end()] + rng.choice(XML_INSERTS) + text[m.end():]
    elif op == 4:
        text = text.replace('band="1"', rng.choice([
            'band="1" subClass="VRTDerivedRasterBand"', 'band="1" subClass="VRTRawRasterBand"',
            'band="1" blockXSize="100000" blockYSize="100000"', 'band="1" dataType="Nope"',
            'band="1" SourceFilename="/etc/passwd"']), 1)
    elif op == 5:
        v = rng.choice(["0", "-5", "1e9", "4194304", "99999999999", "x", "2097152"])
        text = re.sub(r'rasterXSize="\d+"', f'rasterXSize="{v}"', text, count=1)
    elif op == 6:
        text = rng.choice([
            '<!DOCTYPE d [<!ENTITY a "aaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;">]>\n',
            '<!DOCTYPE d [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n',
            '<?xml version="1.0" encoding="UTF-16"?>\n', "\ufeff", "  \n"]) + text
    elif op == 7:
        text = re.sub(r"SourceFilename", rng.choice(["sourcefilename", "SOURCEFILENAME"]), text)
    elif op == 8:  # many sources, or a self-reference
        block = re.search(r"<SimpleSource>.*?</SimpleSource>", text, re.S)
        if block is not None:
            text = text.replace(block.group(0), block.group(0) * rng.choice([2, 300]), 1)
    elif op == 9:
        text = text.replace("cog.tif", rng.choice(["m.vrt", "deep0.vrt"]), 1)
    elif op == 10:
        return _cut(rng, text.encode())
    else:
        return _flip(rng, text.encode()) if rng.random() < 0.5 else _insert(rng, text.encode())
    return text.encode()


# --- the checks -------------------------------------------------------------------------

def render_over(path: Path) -> None:
    """A frame of a small nadir camera above the image: rendered, or refused with
    an error naming the image."""
    scn = load_scenario(path)
    spec = scn.sections["ground"]
    try:
        world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, spec, ()))
        for agl in (60.0, 900.0):  # full resolution, and an overview's
            pose = camera_pose(CAM, 37.0003, -121.9999, GROUND_M + agl, 0.0, 0.0, 10.0,
                               GROUND_M)
            render_frame(world, CAM, pose, 0)
    except (ConfigError, GeoTiffError) as e:
        assert spec.image is not None and os.path.basename(spec.image) in str(e), e


def check_run(path: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = path.read_text().replace("rate_hz: 10}]", "rate_hz: 10, width_px: 64, "
                                                     "height_px: 48}]\n  render_workers: 0")
    path.write_text(text.replace("    views:", "  views:"))
    with watchdog(RUN_LIMIT_S, f"run {path.name}"):
        rc = main(["run", str(path), "--out", str(out), "--duration-s", "0.2",
                   "--backend", "inline", "--no-progress"])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert rc in (0, 1, 2), (rc, err)
    if rc == 1:  # pixels unreadable after all: the camera or the image named
        assert "camera 'belly' of vehicle 'uav1'" in err or "ground.image: " in err, err


@pytest.fixture
def folders(tmp_path: Path) -> Iterator[tuple[Path, Path, Traps]]:
    site, outside = tmp_path / "site", tmp_path / "outside"
    site.mkdir()
    outside.mkdir()
    traps = Traps([outside / "trap.tif", outside / "trap.tif.ovr", site / "pipe.tif"])
    (site / "trap_link.tif").symlink_to(outside / "trap.tif")
    (site / "sub").mkdir()
    try:
        yield site, outside, traps
    finally:
        traps.close()


def fuzz(site: Path, outside: Path, traps: Traps, capsys: pytest.CaptureFixture[str],
         seed: int, n: int) -> dict[str, int]:
    rng = random.Random(seed)
    seeds = corpus(site)
    names = hostile_names(site, outside, traps.port)
    for k in range(5):  # a chain of VRTs, for nesting
        (site / f"deep{k}.vrt").write_text(_vrt([f"deep{k + 1}.vrt" if k < 4 else "cog.tif"]))
    stats = {"mutants": 0, "valid": 0, "rendered": 0, "runs": 0}
    scn = site / "s.yaml"
    for k in range(n):
        kind = rng.choice(["cog.tif", "strip.tif", "plain.tif", "pic.png", "pic.jpg",
                           "mosaic.vrt", "mosaic.vrt", "source"])
        if kind == "mosaic.vrt":
            target, data = "m.vrt", _vrt_text(rng, seeds[kind].decode(), names)
        else:
            seed_name = rng.choice(["cog.tif", "pic.png", "strip.tif", "pic.jpg"]) \
                if kind == "source" else kind
            base = seeds[seed_name]
            op = rng.choice(BINARY + [_other])
            data = op(rng, base, seeds) if op is _other else op(rng, base)
            target = "m" + os.path.splitext(seed_name)[1]
        (site / target).write_bytes(data)
        if kind == "source":  # a valid mosaic naming the mutant
            (site / "m.vrt").write_text(_vrt(["cog.tif", target]))
            target = "m.vrt"
        placed = f", {PLACE}" if target in ("m.png", "m.jpg") or kind == "plain.tif" else ""
        scn.write_text(SCENARIO + f"ground: {{image: {target}{placed}}}\n")
        stats["mutants"] += 1
        what = f"mutant {k} ({kind} -> {target})"
        try:
            ok = check_validate(scn, capsys)
            traps.check(what + ", validate")
            if not ok:
                continue
            stats["valid"] += 1
            with watchdog(RENDER_LIMIT_S, what + ", render"):
                render_over(scn)
            traps.check(what + ", render")
            stats["rendered"] += 1
            if stats["runs"] < RUNS:
                check_run(scn, site.parent / f"run{k}", capsys)
                traps.check(what + ", run")
                stats["runs"] += 1
        except Hang as e:
            raise AssertionError(f"{what}: {e}") from None
    return stats


def test_mutated_rasters_validate_and_render_cleanly(folders, capsys) -> None:
    site, outside, traps = folders
    scale = int(os.environ.get("COSIM_FUZZ_SCALE", "1"))
    t0 = time.monotonic()
    stats = fuzz(site, outside, traps, capsys, seed=29, n=MUTANTS * scale)
    # both outcomes exercised, or the test proves nothing
    assert 0.1 * stats["mutants"] < stats["valid"] < 0.9 * stats["mutants"], stats
    assert stats["runs"] == RUNS, stats
    print(f"\n{stats} in {time.monotonic() - t0:.1f} s")
