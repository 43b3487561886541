"""The limits on scenario files, in one place (the README's "Limits" table).

Scenario files, sweep templates and everything in them are untrusted input:
each limit bounds the memory or the work one file can ask for, or refuses a
value that cannot describe a real run. A value beyond a limit is a config
error with its file line (exit 2), never a traceback, a hang or a silent
change of the value.
"""

from __future__ import annotations

#: horizontal distance of any vehicle, target or commanded point from the
#: scenario origin (m); defined beside the frame it bounds
from cosim.core.geo import MAX_DISTANCE_M  # noqa: F401

#: bytes in a scenario file (a 5000-vehicle scenario listing every vehicle
#: takes about 0.8 MB; formations with ``count`` take one line)
MAX_FILE_BYTES = 2 * 1024 * 1024
#: nesting depth of mappings and lists (bundled scenarios use at most 6)
MAX_DEPTH = 32
#: ``*alias`` references in one file
MAX_ALIASES = 100
#: values in the document once aliases are expanded (an alias "bomb" of
#: nested references multiplies them)
MAX_NODES = 500_000
#: magnitude of a whole number anywhere in the file (a signed 64-bit integer)
MAX_INT = 2 ** 63 - 1
#: magnitude of any number read as a number (fields with their own range are
#: bounded by it; this catches the rest, e.g. ``1e300``)
MAX_NUMBER = 1e9
#: problems printed for one file; the rest are counted
MAX_PROBLEMS_SHOWN = 50
#: problems collected for one file before validation stops looking
MAX_PROBLEMS_KEPT = 1000

#: JSBSim vehicles in one scenario (about 0.45 MiB of memory each for the
#: uav700, so 10,000 vehicles need about 4.5 GiB)
MAX_VEHICLES = 10_000
#: memory one vehicle's flight model takes, measured for the uav700 (MiB)
MIB_PER_VEHICLE = 0.45
#: vehicles of every kind in one scenario: batched vehicles (a few hundred
#: bytes of arrays each) may number up to this
MAX_ALL_VEHICLES = 200_000
#: simulated duration of one run (s): 30 days
MAX_DURATION_S = 30 * 86_400.0
#: physics rate (Hz): JSBSim needs small steps for stable dynamics
PHYSICS_HZ_RANGE = (10.0, 10_000.0)
#: control and log rates (Hz): at least one exchange every 100 s
MIN_EXCHANGE_HZ = 0.01
#: ``seed`` (numpy's SeedSequence takes any size; kept to 32 bits so it
#: prints and reads back everywhere) and a vehicle's ``random_seed`` (JSBSim's
#: ``simulation/randomseed`` is a C int)
MAX_SEED = 2 ** 32 - 1
MAX_VEHICLE_SEED = 2 ** 31 - 2
#: identifiers that become parts of file names (vehicle ids, camera names,
#: target ids, the scenario name): letters, digits, ``_ . -``, not starting
#: with ``.``, at most this long
MAX_NAME_CHARS = 64
#: start heights: no vehicle starts below its ground; a trimmed one (in the
#: air) at least this high above it (m)
MIN_TRIM_AGL_M = 5.0
