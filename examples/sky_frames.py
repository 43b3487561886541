"""The README's sky picture (docs/images/sky.png): the flyover's trucks seen
from 60 m up and 200 m south of the first, looking north 5 deg down and
rolled 10 deg, under the default sun in clear air, through
``atmosphere: {visibility_km: 2}``, and under a low sun ahead (6 deg up,
north-north-east) through 8 km of haze: the sky's colour follows each ray's
elevation, the far ground fades into it, and a low sun dims it and warms it
around the sun.

    python examples/sky_frames.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

from haze_frames import REPO, row, write  # this folder's haze picture: the same view

from cosim.core.camera import CameraSpec
from cosim.world.atmosphere import AtmosphereSpec
from cosim.world.sun import DEFAULT, SunSpec

W, H = 320, 240


def main(out: Path) -> None:
    cam = CameraSpec("oblique", (0,), "gimbal", -5.0, False, 60.0, 46.8, W, H, 10.0, 12)
    low = SunSpec(azimuth_deg=20.0, elevation_deg=6.0)
    write(row(cam, 10.0, ((DEFAULT, None, "sun 50 deg, clear air"),
                          (DEFAULT, AtmosphereSpec(2.0), "sun 50 deg, visibility 2 km"),
                          (low, AtmosphereSpec(8.0), "sun 6 deg ahead, visibility 8 km"))), out)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs/images/sky.png")
