"""Georeferenced ground read with rasterio: files written here with rasterio
(Cloud-Optimized GeoTIFFs with overviews in UTM, Web Mercator, a local
transverse Mercator without EPSG code and WGS-84; a 32 x 32 km mosaic at 1 m/px
as a VRT and as a sparse GeoTIFF, 3 GiB of pixels declared, a few kB on disk).
A magenta square at a known map position must show where pyproj (run
independently of rasterio's PROJ) puts it, in the raster's tiles and in
rendered frames; views of the 32 km raster read only windows (the tile cache
and the process's peak memory stay far below the raster's size); and files
that cannot be placed are refused with their name, the config path and why."""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import textwrap
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import rasterio
import rasterio.shutil
from affine import Affine
from rasterio.crs import CRS
from rasterio.errors import NotGeoreferencedWarning
from rasterio.windows import Window

from cosim.core.camera import CameraSpec, Pose, camera_pose, intrinsics, project, to_camera
from cosim.core.geo import LocalFrame
from cosim.errors import ConfigError
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.renderer.image_layers import GeoRasterLayer
from cosim.scenario import parse_scenario
from cosim.world import geotiff
from cosim.world.ground import GroundSpec

pyproj = pytest.importorskip("pyproj")  # the independent transform (the test extra)

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0
MAGENTA = (255, 0, 255)
SIDE_PX, SQ_ROW, SQ_COL, SQ_PX = 2048, 700, 900, 64  # the file, the square's corner, its side
NADIR = CameraSpec("n", (0,), "nadir", -90.0, False, 60.0, 46.8, 160, 120, 10.0, 12)
WIDE = CameraSpec("w", (0,), "nadir", -90.0, False, 60.0, 46.8, 320, 240, 10.0, 12)
FORWARD = CameraSpec("f", (0,), "forward", -10.0, False, 90.0, 73.7, 160, 120, 10.0, 12)
TMERC = ("+proj=tmerc +lat_0=36.9 +lon_0=-121.8 +k=0.9996 +x_0=500000 +y_0=0 +ellps=WGS84 "
         "+units=m +no_defs")  # a local grid with no EPSG code
#: coordinate system -> its pixel size (0.5 m, or about it)
SYSTEMS = {"EPSG:32610": 0.5, "EPSG:3857": 0.5, TMERC: 0.5, "EPSG:4326": 5e-6}


def _map_xy(crs: str, lat: float, lon: float) -> tuple[float, float]:
    x, y = pyproj.Transformer.from_crs(4326, CRS.from_user_input(crs).to_wkt(),
                                       always_xy=True).transform(lon, lat)
    return float(x), float(y)


def _latlon(crs: str, x: float, y: float) -> tuple[float, float]:
    lon, lat = pyproj.Transformer.from_crs(CRS.from_user_input(crs).to_wkt(), 4326,
                                           always_xy=True).transform(x, y)
    return float(lat), float(lon)


def from_origin(x: float, y: float, dx: float, dy: float) -> Affine:
    """The transform of north-up pixels of dx by dy from the top-left corner (x, y)."""
    return Affine(dx, 0.0, x, 0.0, -dy, y)


def _checker(h: int, w: int) -> np.ndarray:
    """RGB (3, h, w): two greens in 32 px squares (compresses to almost nothing)."""
    j, i = np.mgrid[0:h, 0:w]
    odd = ((i // 32 + j // 32) % 2).astype(bool)
    out = np.empty((3, h, w), np.uint8)
    for k, (a, b) in enumerate(((60, 90), (110, 130), (50, 70))):
        out[k] = np.where(odd, b, a)
    return out


def _cog(path: Path, crs: str, px: float, ul: tuple[float, float]) -> Path:
    """A COG (512 px tiles, overviews 2 and 4) of SIDE_PX square pixels of ``px``
    map units with its top-left corner at ``ul``; a magenta square of SQ_PX at
    (SQ_ROW, SQ_COL)."""
    rgb = _checker(SIDE_PX, SIDE_PX)
    rgb[:, SQ_ROW:SQ_ROW + SQ_PX, SQ_COL:SQ_COL + SQ_PX] = np.array(MAGENTA)[:, None, None]
    plain = path.with_suffix(".plain.tif")
    with rasterio.open(plain, "w", driver="GTiff", width=SIDE_PX, height=SIDE_PX, count=3,
                       dtype="uint8", crs=CRS.from_user_input(crs),
                       transform=from_origin(ul[0], ul[1], px, px)) as ds:
        ds.write(rgb)
    rasterio.shutil.copy(plain, path, driver="COG", compress="deflate", blocksize=512,
                         overview_resampling="average")
    plain.unlink()
    return path


def _square_map_xy(ul: tuple[float, float], px: float) -> tuple[float, float]:
    """The square's centre in the file's coordinates."""
    c = SQ_PX / 2
    return ul[0] + (SQ_COL + c) * px, ul[1] - (SQ_ROW + c) * px


def _magenta_centroid(bgra: np.ndarray) -> tuple[float, float, int]:
    """(x, y, pixels) of the magenta pixels (centres at whole numbers)."""
    b, g, r = (bgra[..., k].astype(int) for k in range(3))
    ys, xs = np.nonzero((r > 180) & (b > 180) & (g < 90))
    if not len(xs):
        return float("nan"), float("nan"), 0
    return float(xs.mean()), float(ys.mean()), len(xs)


def _world(path: Path) -> World:
    spec = GroundSpec(kind="image", image=str(path), geotiff=True)
    return World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, spec, ()))


def _src(world: World) -> geotiff.GeoRaster:
    """The world's georeferenced ground source."""
    layer = world.ground.image
    assert isinstance(layer, GeoRasterLayer)
    return layer.src


def _expected_px(cam: CameraSpec, pose: Pose, lat: float, lon: float) -> np.ndarray:
    """Where the camera model puts the ground point (lat, lon) in the image."""
    ned = np.array(pose.local.geodetic_to_ned(lat, lon, GROUND_M), dtype=float)
    out: np.ndarray = project(intrinsics(cam), to_camera(pose, ned[None, :]))[0]
    return out


@pytest.mark.parametrize("crs", list(SYSTEMS), ids=["utm", "webmercator", "tmerc", "wgs84"])
def test_square_lands_where_pyproj_puts_it(tmp_path: Path, crs: str) -> None:
    px = SYSTEMS[crs]
    x0, y0 = _map_xy(crs, LAT0, LON0)  # the scenario origin some way into the file
    ul = (x0 - 600 * px, y0 + 500 * px)
    path = _cog(tmp_path / "site.tif", crs, px, ul)
    lat, lon = _latlon(crs, *_square_map_xy(ul, px))
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    n, e, _ = frame.geodetic_to_ned(lat, lon, GROUND_M)

    # the raster's own tiles: the square's centre at (n, e) within a pixel
    src = geotiff.GeoRaster(str(path), frame)
    assert src.tiles_made == 0 and src.read_px == 0  # opening reads metadata only
    m = src.m_per_px
    row, col = (src.n0 - n) / m - 0.5, (e - src.e0) / m - 0.5
    r0, c0 = int(row) - 80, int(col) - 80
    img, mask = src.window(0, r0, r0 + 160, c0, c0 + 160)
    x, y, count = _magenta_centroid(img)
    assert count > 1000  # the square: 32 m (Web Mercator: 26 m), 0.4 to 0.5 m pixels
    assert abs(c0 + x - col) < 1.0 and abs(r0 + y - row) < 1.0, (x + c0 - col, y + r0 - row)
    assert mask[80, 80] == 255

    # rendered frames: straight above it (turned 30 deg), beside it, and from high up
    world = _world(path)
    layer = _src(world)
    for dn, de, agl in ((0.0, 0.0, 80.0), (6.0, -9.0, 80.0), (0.0, 0.0, 1400.0)):
        la, lo = frame.place(n + dn, e + de, GROUND_M)
        pose = camera_pose(WIDE, float(la), float(lo), GROUND_M + agl, 0.0, 0.0, 30.0,
                           GROUND_M)
        before = dict(layer.reads)
        out, _ = render_frame(world, WIDE, pose, 0)
        x, y, count = _magenta_centroid(out)
        want = _expected_px(WIDE, pose, lat, lon)
        assert count > 10
        # within 1.5 frame pixels (0.4 m at 80 m; from 1400 m the square is 6 px wide)
        assert abs(x - want[0]) < 1.5 and abs(y - want[1]) < 1.5, (x, y, want, agl)
        if agl > 100:  # from high up: read from an overview, not the full resolution
            new = {f: k - before.get(f, 0) for f, k in layer.reads.items()}
            assert new.get(1, 0) == 0 and sum(new.values()) > 0, new


@dataclass(frozen=True)
class Big:
    vrt: Path
    sparse: Path
    square: tuple[float, float]  # the square's centre (lat, lon)


@pytest.fixture(scope="module")
def big(tmp_path_factory: pytest.TempPathFactory) -> Big:
    """32768 x 32768 px at 1 m in UTM zone 10 around the origin, with a magenta
    square of 256 m about 12 km north-east: as a VRT mosaic (a 512 px background
    stretched over it and the square's own file) and as a sparse tiled GeoTIFF
    (only the square's blocks written; the rest reads as black)."""
    folder = tmp_path_factory.mktemp("big")
    x0, y0 = _map_xy("EPSG:32610", LAT0, LON0)
    ul = (round(x0) - 16384.0, round(y0) + 16384.0)
    sq_col, sq_row, side = 16384 + 12288, 16384 - 12288, 256
    _plain(folder / "bg.tif", _checker(512, 512))
    _plain(folder / "sq.tif", np.broadcast_to(np.array(MAGENTA, np.uint8)[:, None, None],
                                              (3, side, side)).copy())
    wkt = CRS.from_epsg(32610).to_wkt()
    bands = "".join(f"""
        <VRTRasterBand dataType="Byte" band="{b}"><ColorInterp>{ci}</ColorInterp>
          <SimpleSource><SourceFilename relativeToVRT="1">bg.tif</SourceFilename>
            <SourceBand>{b}</SourceBand><SrcRect xOff="0" yOff="0" xSize="512" ySize="512"/>
            <DstRect xOff="0" yOff="0" xSize="32768" ySize="32768"/></SimpleSource>
          <SimpleSource><SourceFilename relativeToVRT="1">sq.tif</SourceFilename>
            <SourceBand>{b}</SourceBand><SrcRect xOff="0" yOff="0" xSize="{side}"
            ySize="{side}"/><DstRect xOff="{sq_col}" yOff="{sq_row}" xSize="{side}"
            ySize="{side}"/></SimpleSource>
        </VRTRasterBand>""" for b, ci in ((1, "Red"), (2, "Green"), (3, "Blue")))
    (folder / "big.vrt").write_text(textwrap.dedent(f"""\
        <VRTDataset rasterXSize="32768" rasterYSize="32768">
          <SRS>{wkt}</SRS>
          <GeoTransform>{ul[0]!r}, 1.0, 0.0, {ul[1]!r}, 0.0, -1.0</GeoTransform>{bands}
        </VRTDataset>
        """))
    with rasterio.open(folder / "sparse.tif", "w", driver="GTiff", width=32768, height=32768,
                       count=3, dtype="uint8", crs="EPSG:32610",
                       transform=from_origin(ul[0], ul[1], 1.0, 1.0), tiled=True,
                       blockxsize=256, blockysize=256, compress="deflate", sparse_ok=True,
                       photometric="RGB") as ds:
        ds.write(np.broadcast_to(np.array(MAGENTA, np.uint8)[:, None, None], (3, side, side)),
                 window=Window(sq_col, sq_row, side, side))
    c = side / 2
    return Big(folder / "big.vrt", folder / "sparse.tif",
               _latlon("EPSG:32610", ul[0] + sq_col + c, ul[1] - sq_row - c))


def _plain(path: Path, rgb: np.ndarray) -> None:
    """A TIFF with no georeference."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", driver="GTiff", width=rgb.shape[2], height=rgb.shape[1],
                           count=3, dtype="uint8", photometric="RGB") as ds:
            ds.write(rgb)


def _peak_rss_mb() -> float:
    """This process's peak resident memory (MB): Linux's VmHWM, which starts afresh
    in a new program (getrusage's ru_maxrss carries the peak of the process that
    forked it across exec), else getrusage."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kB


#: (where: "square" or (lat, lon), camera, height above ground, yaw_deg)
VIEWS: list[tuple[str | tuple[float, float], CameraSpec, float, float]] = [
         ("square", NADIR, 120.0, 0.0), ((LAT0, LON0), NADIR, 150.0, 45.0),
         ((LAT0 - 0.1, LON0 - 0.12), NADIR, 1500.0, 0.0),
         ((LAT0 + 0.05, LON0), FORWARD, 300.0, 20.0),
         ((LAT0 - 0.05, LON0 + 0.1), FORWARD, 1500.0, 200.0)]


def _measure(path: str, lat: float, lon: float, small: str) -> dict[str, object]:
    """Run in a fresh process (its peak RSS its own): warm up on ``small``, then open
    the raster at ``path`` and render VIEWS; what was read and held, the peak RSS
    growth, and where the square (at ``lat``, ``lon``) showed."""
    pose = camera_pose(NADIR, LAT0, LON0, GROUND_M + 100.0, 0.0, 0.0, 0.0, GROUND_M)
    render_frame(_world(Path(small)), NADIR, pose, 0)  # imports, GDAL, the renderer's buffers
    rss0 = _peak_rss_mb()
    world = _world(Path(path))
    src = _src(world)
    out: dict[str, object] = {"size": [src.ref.width_px, src.ref.height_px],
                              "opened_reads": [src.tiles_made, src.read_px]}
    for where, cam, agl, yaw in VIEWS:
        la, lo = (lat, lon) if isinstance(where, str) else where
        pose = camera_pose(cam, la, lo, GROUND_M + agl, 0.0, 0.0, yaw, GROUND_M)
        img, _ = render_frame(world, cam, pose, 0)
        if where == "square":
            x, y, count = _magenta_centroid(img)
            out["square"] = [x, y, count, *_expected_px(cam, pose, lat, lon).tolist()]
    out.update(rss_growth_mb=_peak_rss_mb() - rss0, tiles=src.tiles_made, read_px=src.read_px,
               peak_cache=src.peak_cache_bytes, max_cache=src.max_bytes,
               tile_bytes=src.tile_px ** 2 * 5)
    return out


@pytest.mark.parametrize("kind", ["vrt", "sparse"])
@pytest.mark.integration
def test_32km_raster_is_read_by_windows(tmp_path: Path, big: Big,
                                        kind: str) -> None:
    path = big.vrt if kind == "vrt" else big.sparse
    assert path.stat().st_size < 1 << 20  # a few kB on disk
    full_bytes = 32768 * 32768 * 3  # the raster's pixels: 3 GiB
    small = _cog(tmp_path / "small.tif", "EPSG:32610", 0.5,
                 _map_xy("EPSG:32610", LAT0 + 0.001, LON0 - 0.001))
    lat, lon = big.square
    # a fresh process: this one's peak RSS holds whatever ran before
    run = ("import importlib.util, json, sys; "
           "s = importlib.util.spec_from_file_location('t', sys.argv[1]); "
           "m = sys.modules['t'] = importlib.util.module_from_spec(s); s.loader.exec_module(m); "
           "print(json.dumps(m._measure(sys.argv[2], float(sys.argv[3]), float(sys.argv[4]),"
           " sys.argv[5])))")
    done = subprocess.run([sys.executable, "-c", run, __file__, str(path), repr(lat), repr(lon),
                           str(small)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got["size"] == [32768, 32768]
    assert got["opened_reads"] == [0, 0]  # opening read metadata only
    x, y, count, want_x, want_y = got["square"]
    # the square 12 km out, below the camera where pyproj says (2 px: 0.3 m)
    assert count > 100 and abs(x - want_x) < 2 and abs(y - want_y) < 2, got["square"]
    print(f"\n{kind}: {got['tiles']} tiles made, {got['read_px'] * 3 / 2**20:.1f} MB read, "
          f"tile cache peak {got['peak_cache'] / 2**20:.1f} MB, peak RSS growth "
          f"{got['rss_growth_mb']:.0f} MB (raster {full_bytes / 2**30:.0f} GiB)")
    assert got["peak_cache"] <= got["max_cache"] + got["tile_bytes"]
    assert got["read_px"] * 3 < full_bytes / 50  # windows, never the raster
    assert got["rss_growth_mb"] < 300, f"peak RSS grew {got['rss_growth_mb']:.0f} MB"


def test_bad_rasters_are_refused_with_why(tmp_path: Path, big: Big) -> None:
    # the scenario a ground section is checked in (here: this module also runs alone, in
    # a subprocess, where test_geotiff is not importable)
    from test_geotiff import SCENARIO, _errors

    site = _cog(tmp_path / "site.tif", "EPSG:32610", 0.5, _map_xy("EPSG:32610", LAT0, LON0))
    scn = parse_scenario(SCENARIO + "ground: {image: site.tif}\n", str(tmp_path / "s.yaml"))
    assert scn.sections["ground"].geotiff
    (tmp_path / "vrt").symlink_to(big.vrt.parent)
    # the mosaic lies in a folder of its own, which the scenario allows
    scn = parse_scenario(SCENARIO + "ground: {image: vrt/big.vrt, image_folders: [vrt]}\n",
                         str(tmp_path / "s.yaml"))
    assert scn.sections["ground"].geotiff  # a VRT places itself too

    def refused(name: str, *why: str, ground: str | None = None) -> None:
        msg = _errors(tmp_path, ground or f"ground: {{image: {name}}}\n")
        assert "s.yaml:" in msg and "ground" in msg and name in msg, msg
        for w in why:
            assert w in msg, msg

    (tmp_path / "junk.tif").write_bytes(b"II*\x00 not really a TIFF")
    refused("junk.tif", "cannot read it as a raster image")
    _plain(tmp_path / "plain.tif", _checker(64, 64))
    refused("plain.tif", "no GeoTIFF georeference", "origin and m_per_px")
    with rasterio.open(tmp_path / "local.tif", "w", driver="GTiff", width=64, height=64, count=3,
                       dtype="uint8", transform=from_origin(100, 200, 1, 1),
                       crs=CRS.from_wkt('LOCAL_CS["site grid",UNIT["metre",1]]')) as ds:
        ds.write(_checker(64, 64))
    refused("local.tif", "'site grid'", "no EPSG code", "cannot be placed on the Earth",
            "gdalwarp -t_srs EPSG:4326")
    cut = tmp_path / "cut.tif"  # the header and directories, not the pixels
    cut.write_bytes(site.read_bytes()[:1200])
    refused("cut.tif", "cannot read")
    refused("big.vrt", "carries its own georeference",
            ground="ground: {image: vrt/big.vrt, image_folders: [vrt], m_per_px: 1.0}\n")
    refused("big.vrt", "outside the allowed folders", "ground.image_folders",
            ground="ground: {image: vrt/big.vrt}\n")
    # a mosaic whose piece went missing: the window that needs it says so
    broken = tmp_path / "broken.vrt"
    broken.write_text(big.vrt.read_text().replace(
        'relativeToVRT="1">sq.tif', f'relativeToVRT="0">{tmp_path}/gone.tif'))
    src = geotiff.GeoRaster(str(broken), LocalFrame(LAT0, LON0, GROUND_M))
    lat, lon = big.square
    n, e, _ = src.frame.geodetic_to_ned(lat, lon, GROUND_M)
    r, c = int((src.n0 - n) / src.m_per_px), int((e - src.e0) / src.m_per_px)
    with pytest.raises(geotiff.GeoTiffError, match=r"broken\.vrt: cannot read its pixels"):
        src.window(0, r, r + 8, c, c + 8)
    # and the renderer's world says which file
    with pytest.raises(ConfigError, match=r"ground\.image: .*plain\.tif: no GeoTIFF"):
        _world(tmp_path / "plain.tif")


def test_nodata_16bit_and_palette_files(tmp_path: Path) -> None:
    """16-bit bands scaled to their range, nodata left to the procedural ground, a
    palette through its colour table."""
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    x0, y0 = _map_xy("EPSG:32610", LAT0, LON0)
    t = from_origin(x0 - 50, y0 + 50, 0.5, 0.5)
    kw = dict(driver="GTiff", width=200, height=200, count=1, crs="EPSG:32610", transform=t)
    a = np.full((1, 200, 200), 1000, np.uint16)
    a[0, :, 100:] = 3000
    a[0, :50] = 0  # nodata: the top quarter
    with rasterio.open(tmp_path / "u16.tif", "w", dtype="uint16", nodata=0, **kw) as ds:
        ds.write(a)
    img, mask, n0, e0, m = geotiff.resample(str(tmp_path / "u16.tif"),
                                            geotiff.read_georef(str(tmp_path / "u16.tif")), frame)
    assert mask[:40].max() == 0 and mask[60:190, 10:190].min() == 255
    assert img[120, 20, 0] == 0 and img[120, 180, 0] == 255  # 1000 .. 3000 -> 0 .. 255
    p = np.zeros((1, 200, 200), np.uint8)
    p[0, :, 100:] = 1
    with rasterio.open(tmp_path / "pal.tif", "w", dtype="uint8", photometric="palette",
                       **kw) as ds:
        ds.write(p)
        ds.write_colormap(1, {0: (255, 0, 0, 255), 1: (0, 0, 255, 255)})
    img, *_ = geotiff.resample(str(tmp_path / "pal.tif"),
                               geotiff.read_georef(str(tmp_path / "pal.tif")), frame)
    assert tuple(img[100, 20, :3]) == (0, 0, 255) and tuple(img[100, 180, :3]) == (255, 0, 0)
