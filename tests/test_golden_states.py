"""Every bundled scenario, run briefly, gives the states and events recorded
in ``tests/data/golden_states.json`` bit for bit: the record of behaviour a
refactoring must not change (``python benchmarks/golden_states.py`` checks
all of them; ``--record`` writes the record anew, for a change that is meant
to alter behaviour, said so in its commit)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))

import golden_states as golden  # noqa: E402

RECORD = json.loads(golden.RECORD.read_text())


@pytest.mark.parametrize("path", golden.scenarios(), ids=golden.key)
def test_a_bundled_scenario_does_what_it_did(path: Path, tmp_path: Path) -> None:
    here = golden.environment()
    if {k: here[k] for k in ("jsbsim", "numpy", "machine")} != {
            k: RECORD["environment"][k] for k in ("jsbsim", "numpy", "machine")}:
        pytest.skip(f"the record was made with {RECORD['environment']}, this is {here}: "
                    f"floating point may differ (python benchmarks/golden_states.py --record)")
    want = RECORD["runs"].get(golden.key(path))
    assert want is not None, f"{golden.key(path)} is not in the record: record it"
    assert golden.run_one(path, tmp_path / "run") == want
