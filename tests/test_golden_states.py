"""Every bundled scenario, run briefly, gives the states and events recorded
in ``tests/data/golden_states.json`` bit for bit: the record of behaviour a
refactoring must not change (``python benchmarks/golden_states.py`` checks
all of them; ``--record`` writes the record anew, for a change that is meant
to alter behaviour, said so in its commit)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))

import golden_states as golden  # noqa: E402

HERE = golden.environment()
RECORD = golden.matching(HERE)


pytestmark = pytest.mark.integration  # every bundled scenario flown to its end


@pytest.mark.parametrize("path", golden.scenarios(), ids=golden.key)
def test_a_bundled_scenario_does_what_it_did(path: Path, tmp_path: Path) -> None:
    if RECORD is None:
        made = [r["environment"] for r in golden.records()]
        pytest.skip(f"the records were made with {made}, this is {HERE}: floating point "
                    f"may differ (python benchmarks/golden_states.py --record)")
    want = RECORD["runs"].get(golden.key(path))
    if want is None:  # a scenario newer than this environment's record
        pytest.skip(f"{golden.key(path)} is newer than the record for {HERE}: record it on "
                    f"such a machine (python benchmarks/golden_states.py --record)")
    assert golden.run_one(path, tmp_path / "run") == want


def test_the_records_are_found_by_their_environment() -> None:
    """A record applies only where jsbsim, numpy, the machine and numpy's
    SIMD extensions all match."""
    recs = golden.records()
    assert recs, "no golden records"
    for r in recs:
        env = dict(r["environment"])
        assert golden.matching(env) is r or golden.matching(env) == r
        assert golden.matching({**env, "simd": env["simd"] + " X"}) is None
