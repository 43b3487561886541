"""Record (or check) the states and events of every bundled scenario, run
briefly, as digests (``cosim.logs.digest``): the record of what a change
must not alter. ``tests/test_golden_states.py`` compares every run with
``tests/data/golden_states.json``.

    python benchmarks/golden_states.py            # check against the record
    python benchmarks/golden_states.py --record   # write the record anew

Record anew only for a change meant to alter behaviour, and say so in its
commit. The record names the jsbsim and numpy versions and the machine it
was made with: floating point may differ elsewhere, and the test skips then.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
RECORD = REPO / "tests" / "data" / "golden_states.json"
#: simulated seconds per scenario (capped at its own duration): long enough for
#: schedules, swarm phases and missions to act; the 1000-vehicle one briefly
SECONDS = {"swarm1000.yaml": 2.0}
DEFAULT_SECONDS = 20.0


def scenarios() -> list[Path]:
    return sorted((REPO / "scenarios").rglob("*.yaml"))


def environment() -> dict[str, str]:
    import jsbsim
    import numpy

    return {"jsbsim": jsbsim.__version__, "numpy": numpy.__version__,
            "machine": platform.machine(), "python": platform.python_version()[:4]}


def run_one(path: Path, out: Path) -> dict[str, Any]:
    """Run ``path`` briefly (inline backend) into ``out``; its digests."""
    from cosim.logs.digest import run_digest
    from cosim.scenario import load_scenario
    from cosim.sync import run_scenario

    scn = load_scenario(path)
    seconds = min(scn.duration_s, SECONDS.get(path.name, DEFAULT_SECONDS))
    res = run_scenario(scn.with_duration(seconds), out, backend="inline")
    if res.stop_reason != "completed":
        raise RuntimeError(f"{path.name}: {res.stop_reason}: {res.error}")
    return {"seconds": seconds, **run_digest(out)}


def key(path: Path) -> str:
    return str(path.relative_to(REPO / "scenarios"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record", action="store_true", help="write the record anew")
    a = ap.parse_args(argv)
    got: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, path in enumerate(scenarios()):
            got[key(path)] = run_one(path, Path(tmp) / str(i))
            print(f"{key(path)}: {got[key(path)]['states'][:16]} "
                  f"({got[key(path)]['rows']} rows)", flush=True)
    if a.record:
        RECORD.parent.mkdir(parents=True, exist_ok=True)
        RECORD.write_text(json.dumps({"environment": environment(), "runs": got}, indent=1,
                                     sort_keys=True) + "\n")
        print(f"recorded {len(got)} scenarios in {RECORD}")
        return 0
    want = json.loads(RECORD.read_text())["runs"]
    bad = [k for k in sorted(set(want) | set(got)) if want.get(k) != got.get(k)]
    for k in bad:
        print(f"DIFFERENT: {k}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
