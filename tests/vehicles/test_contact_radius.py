"""A JSBSim vehicle's contact radius (how far its farthest ground-contact
point is from its CG, which decides when the ground check may be skipped),
read from each contact unit's position properties, is the one computed from
the units' locations as JSBSim's ``get_location()`` returns them, for models
with landing gear (BOGEY units), structural contacts (STRUCTURE) or both."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from cosim.core.units import FT_TO_M
from cosim.vehicles.jsb import find_model, new_fdm
from cosim.vehicles.jsbsim_model import contact_radius_m


@pytest.mark.parametrize("name", ["uav700", "F450", "c172p"])
def test_the_radius_reaches_the_farthest_contact_point(name: str) -> None:
    fdm = new_fdm(find_model(name), 1 / 120)
    fdm["ic/h-sl-ft"] = 1000.0
    assert fdm.run_ic()
    gr = fdm.get_ground_reactions()
    cg = (fdm["inertia/cg-x-in"], fdm["inertia/cg-y-in"], fdm["inertia/cg-z-in"])
    points = []
    for i in range(gr.get_num_gear_units()):
        with warnings.catch_warnings():  # a numpy.matrix
            warnings.simplefilter("ignore", PendingDeprecationWarning)
            points.append(np.asarray(gr.get_gear_unit(i).get_location()).ravel().tolist())
    assert len(points) >= 3
    want_m = max(math.dist(p, cg) for p in points) * (FT_TO_M / 12.0)
    assert contact_radius_m(fdm) == want_m  # the same doubles, bit for bit
