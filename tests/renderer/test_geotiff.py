"""GeoTIFF ground images: the tags read back, each file pixel placed where its
coordinates say (checked with the scenario frame's own geodetic conversion and,
for UTM, pyproj's projection run the other way), the covered area, the
config's errors, and a rendered frame showing the file's colours."""

from __future__ import annotations

import math
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, TiffImagePlugin, TiffTags

from cosim.core.camera import CameraSpec, camera_pose
from cosim.core.geo import LocalFrame
from cosim.errors import ConfigError
from cosim.renderer.frame import World, WorldSpec, render_frame
from cosim.scenario import parse_scenario
from cosim.world import geotiff
from cosim.world.ground import GroundSpec

LAT0, LON0, GROUND_M = 37.0, -122.0, 10.0
W, H = 128, 96  # the file's pixels: red 2 x column, green 2 x row (a position code)


def _gradient() -> np.ndarray:
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[..., 0] = 2 * np.arange(W)[None, :]
    rgb[..., 1] = 2 * np.arange(H)[:, None]
    rgb[..., 2] = 128
    return rgb


def _write(path: Path, keys: list[int], tiepoint: tuple[float, ...] | None = None,
           scale: tuple[float, ...] | None = None,
           transform: tuple[float, ...] | None = None) -> Path:
    """A GeoTIFF of the gradient with these GeoKeys (key, value pairs, flat)."""
    ifd = TiffImagePlugin.ImageFileDirectory_v2()
    if tiepoint is not None:
        ifd[geotiff.TAG_TIEPOINT] = tiepoint
        ifd.tagtype[geotiff.TAG_TIEPOINT] = TiffTags.DOUBLE
    if scale is not None:
        ifd[geotiff.TAG_PIXEL_SCALE] = scale
        ifd.tagtype[geotiff.TAG_PIXEL_SCALE] = TiffTags.DOUBLE
    if transform is not None:
        ifd[geotiff.TAG_TRANSFORM] = transform
        ifd.tagtype[geotiff.TAG_TRANSFORM] = TiffTags.DOUBLE
    n = len(keys) // 2
    directory = [1, 1, 0, n]
    for k in range(n):
        directory += [keys[2 * k], 0, 1, keys[2 * k + 1]]
    ifd[geotiff.TAG_GEOKEYS] = tuple(directory)
    ifd.tagtype[geotiff.TAG_GEOKEYS] = TiffTags.SHORT
    Image.fromarray(_gradient()).save(path, tiffinfo=ifd)
    return path


GEOGRAPHIC = [1024, 2, 1025, 1, 2048, 4326]
LON_UL, LAT_UL, DLON, DLAT = LON0 - 0.002, LAT0 + 0.0015, 3e-5, 1.5e-5  # 2.7 x 1.7 m pixels


def _geographic(tmp_path: Path) -> Path:
    return _write(tmp_path / "geo.tif", GEOGRAPHIC, (0, 0, 0, LON_UL, LAT_UL, 0), (DLON, DLAT, 0))


def _sample(img: np.ndarray, n0: float, e0: float, mpp: float, n: np.ndarray,
            e: np.ndarray) -> np.ndarray:
    """Bilinear samples (k x 3, float) of the resampled image at scenario points:
    pixel (row, col) covers north n0 - (row + 1) mpp .. n0 - row mpp, east
    e0 + col mpp .. e0 + (col + 1) mpp."""
    x, y = (e - e0) / mpp - 0.5, (n0 - n) / mpp - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    px = img[..., :3].astype(np.float64)
    return ((1 - fy) * ((1 - fx) * px[y0, x0] + fx * px[y0, x0 + 1])
            + fy * ((1 - fx) * px[y0 + 1, x0] + fx * px[y0 + 1, x0 + 1]))


def _check_placement(img: np.ndarray, n0: float, e0: float, mpp: float, n: np.ndarray,
                     e: np.ndarray, col: np.ndarray, row: np.ndarray) -> None:
    """The image shows, at scenario (n, e), the file's position code of the file
    position (col, row) (OpenCV's convention: pixel centres at whole numbers).
    Within 0.8 of a code unit, 0.4 px: a half-pixel slip is a whole unit."""
    got = _sample(img, n0, e0, mpp, n, e)
    np.testing.assert_allclose(got[:, 2], 2 * col, atol=0.8)  # BGR: red is the column
    np.testing.assert_allclose(got[:, 1], 2 * row, atol=0.8)
    np.testing.assert_allclose(got[:, 0], 128, atol=0.6)


def _file_points(seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(2, W - 3, 200), rng.uniform(2, H - 3, 200)


def test_reads_the_georeference(tmp_path: Path) -> None:
    ref = geotiff.read_georef(str(_geographic(tmp_path)))
    assert ref.epsg == 4326 and (ref.width_px, ref.height_px) == (W, H)
    assert ref.affine == pytest.approx((DLON, 0.0, LON_UL, 0.0, -DLAT, LAT_UL), rel=0, abs=1e-10)
    # the same by ModelTransformation, and by a tiepoint at another pixel
    m = (DLON, 0, 0, LON_UL, 0, -DLAT, 0, LAT_UL, 0, 0, 0, 0, 0, 0, 0, 1)
    by_matrix = _write(tmp_path / "m.tif", GEOGRAPHIC, transform=tuple(float(v) for v in m))
    assert geotiff.read_georef(str(by_matrix)).affine == pytest.approx(ref.affine, rel=0, abs=1e-10)
    moved = _write(tmp_path / "t.tif", GEOGRAPHIC,
                   (10, 20, 0, LON_UL + 10 * DLON, LAT_UL - 20 * DLAT, 0), (DLON, DLAT, 0))
    assert geotiff.read_georef(str(moved)).affine == pytest.approx(ref.affine, rel=0, abs=1e-10)
    # pixel is point: the tiepoint names the first pixel's centre, half a pixel in
    point = _write(tmp_path / "p.tif", [1024, 2, 1025, 2, 2048, 4326],
                   (0, 0, 0, LON_UL + DLON / 2, LAT_UL - DLAT / 2, 0), (DLON, DLAT, 0))
    assert geotiff.read_georef(str(point)).affine == pytest.approx(ref.affine, rel=0, abs=1e-10)


def test_geographic_file_lands_where_its_coordinates_say(tmp_path: Path) -> None:
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    path = _geographic(tmp_path)
    img, mask, n0, e0, mpp = geotiff.resample(str(path), geotiff.read_georef(str(path)), frame)
    assert mpp == pytest.approx(math.sqrt(2.66 * 1.665), rel=0.01)
    col, row = _file_points()
    lat, lon = LAT_UL - (row + 0.5) * DLAT, LON_UL + (col + 0.5) * DLON  # pixel centres
    n, e, _ = frame.geodetic_to_ned(lat, lon, GROUND_M)
    _check_placement(img, n0, e0, mpp, n, e, col, row)
    # covered inside the outline, not beyond it (a pixel clear of the edge)
    inside_n, inside_e, _ = frame.geodetic_to_ned(LAT_UL - 0.5 * H * DLAT,
                                                  LON_UL + 0.5 * W * DLON, GROUND_M)
    r, c = int((n0 - inside_n) / mpp), int((inside_e - e0) / mpp)
    assert mask[r, c] == 255
    corner_n, corner_e, _ = frame.geodetic_to_ned(LAT_UL, LON_UL, GROUND_M)  # north-west
    assert abs(corner_n - n0) < mpp and abs(corner_e - e0) < mpp
    assert mask[0, mask.shape[1] - 1] == 0 or mask[mask.shape[0] - 1, 0] == 0 \
        or mask.all()  # a lat/lon box is close to square on the grid
    assert 0.95 < mask.mean() / 255 <= 1.0


def test_projected_file_is_turned_by_its_grid_convergence(tmp_path: Path) -> None:
    pyproj = pytest.importorskip("pyproj")
    to_utm = pyproj.Transformer.from_crs(4326, 32610, always_xy=True)  # UTM zone 10 north
    x_ul, y_ul = to_utm.transform(LON0 - 0.003, LAT0 + 0.002)
    path = _write(tmp_path / "utm.tif", [1024, 1, 1025, 1, 3072, 32610],
                  (0, 0, 0, x_ul, y_ul, 0), (5.0, 4.0, 0))
    frame = LocalFrame(LAT0, LON0, GROUND_M)
    img, mask, n0, e0, mpp = geotiff.resample(str(path), geotiff.read_georef(str(path)), frame)
    col, row = _file_points(2)
    x, y = x_ul + (col + 0.5) * 5.0, y_ul - (row + 0.5) * 4.0
    lon, lat = pyproj.Transformer.from_crs(32610, 4326, always_xy=True).transform(x, y)
    n, e, _ = frame.geodetic_to_ned(lat, lon, GROUND_M)
    _check_placement(img, n0, e0, mpp, n, e, col, row)
    # the grid is turned about 0.6 deg from true north here (a degree east of the
    # zone's central meridian): the file's outline leaves uncovered corners
    assert mask[0, 0] == 0 or mask[0, -1] == 0
    assert 0.94 < mask.mean() / 255 < 0.99


def test_rendered_frame_shows_the_file(tmp_path: Path) -> None:
    path = _geographic(tmp_path)
    spec = GroundSpec(kind="image", image=str(path), geotiff=True)
    world = World(WorldSpec(LAT0, LON0, GROUND_M, 1, 120.0, spec, ()))
    cam = CameraSpec("c", (0,), "nadir", -90.0, False, 40.0, 30.6, 64, 48, 10.0, 12)
    col, row = 40.0, 30.0  # a point of the file straight below the camera
    lat, lon = LAT_UL - (row + 0.5) * DLAT, LON_UL + (col + 0.5) * DLON
    pose = camera_pose(cam, lat, lon, GROUND_M + 60.0, 0.0, 0.0, 0.0, GROUND_M)
    img, _ = render_frame(world, cam, pose, 0)
    b, g, r = img[23:25, 31:33, :3].reshape(-1, 3).mean(axis=0)  # the image centre
    assert abs(r - 2 * col) < 3 and abs(g - 2 * row) < 3 and abs(b - 128) < 2
    # far from the file: the procedural ground, not the file's edge colours smeared
    far = camera_pose(cam, LAT0 - 0.01, LON0, GROUND_M + 60.0, 0.0, 0.0, 0.0, GROUND_M)
    img, _ = render_frame(world, cam, far, 0)
    assert abs(float(img[..., 0].mean()) - 128) > 20


SCENARIO = textwrap.dedent("""\
    schema_version: 1
    name: g
    origin: {lat_deg: 37.0, lon_deg: -122.0, ground_alt_m: 10}
    duration_s: 1
    vehicles:
      - id: uav1
        model: uav700
        init: {north_m: 0, east_m: 0, alt_agl_m: 100, heading_deg: 0, airspeed_kt: 100}
    cameras:
      views: [{name: belly, vehicles: uav1, mount: nadir, rate_hz: 10}]
    """)


def _errors(tmp_path: Path, ground: str) -> str:
    with pytest.raises(ConfigError) as e:
        parse_scenario(SCENARIO + ground, str(tmp_path / "s.yaml"))
    return str(e.value)


def test_config_accepts_a_geotiff_and_says_what_is_wrong(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    _geographic(tmp_path)
    scn = parse_scenario(SCENARIO + "ground: {image: geo.tif}\n", str(tmp_path / "s.yaml"))
    assert scn.sections["ground"].geotiff and scn.sections["ground"].kind == "image"
    # a GeoTIFF placed by hand as well: ambiguous
    msg = _errors(tmp_path, "ground: {image: geo.tif, m_per_px: 1.0}\n")
    assert "carries its own georeference" in msg
    # a TIFF with no georeference and no placement
    Image.fromarray(_gradient()).save(tmp_path / "plain.tif")
    msg = _errors(tmp_path, "ground: {image: plain.tif}\n")
    assert "no GeoTIFF georeference" in msg and "origin and m_per_px" in msg
    # ... which is fine once placed by hand (a plain picture)
    by_hand = "ground: {image: plain.tif, m_per_px: 0.5, origin: {north_m: 0, east_m: 0}}\n"
    scn = parse_scenario(SCENARIO + by_hand, str(tmp_path / "s.yaml"))
    assert not scn.sections["ground"].geotiff
    # a projected system needs no pyproj: rasterio brings its own PROJ
    _write(tmp_path / "utm.tif", [1024, 1, 1025, 1, 3072, 32610], (0, 0, 0, 5e5, 4e6, 0),
           (5.0, 5.0, 0))
    monkeypatch.setitem(sys.modules, "pyproj", None)  # import fails
    scn = parse_scenario(SCENARIO + "ground: {image: utm.tif}\n", str(tmp_path / "s.yaml"))
    assert scn.sections["ground"].geotiff
    # a user-defined system (a local one: not on the Earth)
    _write(tmp_path / "user.tif", [1024, 1, 1025, 1, 3072, 32767], (0, 0, 0, 0, 0, 0),
           (1.0, 1.0, 0))
    msg = _errors(tmp_path, "ground: {image: user.tif}\n")
    assert "user.tif" in msg and "no EPSG code" in msg and "gdalwarp -t_srs EPSG:4326" in msg
