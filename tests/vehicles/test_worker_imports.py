"""A physics worker imports what building and stepping its vehicles needs,
not the MAVLink side of their classes (cosim.mavlink, pymavlink: 0.2-0.3 s
of a worker's start-up, on the path of every pool's start), nor the
catalog's YAML; a class's MAVLink personality is still there when read."""

from __future__ import annotations

import pickle
import subprocess
import sys

from cosim.bench.fleet import bench_specs
from cosim.vehicles.registry import get_class, vehicle_classes

#: what a worker does (cosim.fdm_pool.process._worker_main): its specs arrive
#: pickled, it builds a shard from them and steps it
WORKER = """
import pickle, sys
import numpy as np
import cosim.fdm_pool.process
from cosim.fdm_pool.shard import Shard
specs = pickle.loads(sys.stdin.buffer.read())
shard = Shard.build(specs, 1 / 120, ())
out = np.zeros((len(specs), shard.n_columns))
shard.exchange(None, 4, out)
print(" ".join(sorted(m for m in sys.modules
                      if m.split(".")[0] in ("pymavlink", "yaml")
                      or m.startswith("cosim.mavlink"))))
"""


def test_a_worker_building_and_stepping_fixed_wings_imports_no_mavlink() -> None:
    specs = bench_specs(2, "uav700") + bench_specs(1, "c172p", vehicle_class="jsbsim")
    assert {s.vehicle_class for s in specs} == {"fixed_wing", "jsbsim"}
    proc = subprocess.run([sys.executable, "-c", WORKER], input=pickle.dumps(specs),
                          capture_output=True, timeout=120)
    assert proc.returncode == 0, proc.stderr.decode()
    assert proc.stdout.decode().split() == []


def test_the_classes_personalities_are_there_when_read() -> None:
    for name in ("fixed_wing", "jsbsim", "quadrotor"):
        cls = get_class(name)
        assert cls is vehicle_classes()[name]
        assert cls.mavlink is not None and cls.mavlink is cls.mavlink
    from cosim.vehicles.fixed_wing.mavlink import ARDUPLANE, ARDUPLANE_NO_AUTOPILOT

    assert get_class("fixed_wing").mavlink is ARDUPLANE
    assert get_class("jsbsim").mavlink is ARDUPLANE_NO_AUTOPILOT
