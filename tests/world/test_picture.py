"""A ground picture placed by hand lies on the image grid its origin and
m_per_px say (the convention a GeoTIFF's ``GeoRaster`` shares), halved level by
level; one that does not decode is refused naming ``ground.image``."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from cosim.core.geo import LocalFrame
from cosim.errors import ConfigError
from cosim.world.geotiff import GeoRaster
from cosim.world.ground import GroundSpec, open_image
from cosim.world.image_grid import ImageGrid
from cosim.world.picture import Picture

FRAME = LocalFrame(37.0, -122.0, 10.0)


def _picture(tmp_path: Path) -> Path:
    img = np.zeros((30, 40, 3), np.uint8)
    img[10, 20] = (255, 0, 255)
    cv2.imwrite(str(tmp_path / "pic.png"), img)
    return tmp_path / "pic.png"


def test_a_picture_lies_where_its_origin_and_pixel_size_put_it(tmp_path: Path) -> None:
    pic = Picture(str(_picture(tmp_path)), (str(tmp_path),), FRAME, 0.5, (100.0, -50.0))
    # pixel (row 10, col 20) is centred 10.5 pixels south and 20.5 east of the corner
    n, e = 100.0 - 10.5 * 0.5, -50.0 + 20.5 * 0.5
    assert pic.ne_to_px(0) @ [n, e, 1.0] == pytest.approx([20.0, 10.0, 1.0])
    assert pic.ne_to_px(1) @ [n, e, 1.0] == pytest.approx([(20.5 / 2) - 0.5, (10.5 / 2) - 0.5, 1])
    assert pic.ne_to_px(0, 4, 8) @ [n, e, 1.0] == pytest.approx([12.0, 6.0, 1.0])
    assert pic.levels[0][10, 20].tolist() == [255, 0, 255, 255]
    assert [lv.shape[:2] for lv in pic.levels] == [(30, 40), (15, 20), (8, 10), (4, 5)]
    assert pic.bounds_ne == (100.0 - 15.0, 100.0, -50.0, -50.0 + 20.0)
    assert [pic.level_for(g) for g in (0.1, 0.5, 1.0, 1.7, 100.0)] == [0, 0, 1, 2, 3]
    # placed by latitude and longitude: the same corner
    la, lo = FRAME.place(100.0, -50.0, FRAME.alt_m)
    by_ll = Picture(str(tmp_path / "pic.png"), (str(tmp_path),), FRAME, 0.5,
                    origin_latlon_deg=(float(la), float(lo)))
    assert (by_ll.n0, by_ll.e0) == pytest.approx((100.0, -50.0), abs=1e-6)
    assert isinstance(pic, ImageGrid) and issubclass(GeoRaster, ImageGrid)


def test_a_picture_that_does_not_decode_is_refused_naming_the_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.png"
    data = bytearray(_picture(tmp_path).read_bytes())
    data[40:] = bytes(len(data) - 40)  # its header whole, its pixels gone
    bad.write_bytes(bytes(data))
    spec = GroundSpec(kind="image", image=str(bad), m_per_px=0.5,
                      image_folders=(str(tmp_path),))
    with pytest.raises(ConfigError, match=r"^ground\.image: cannot read .*bad\.png as an image"):
        open_image(spec, FRAME)
