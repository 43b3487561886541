"""Record (or check) the states and events of every bundled scenario, run
briefly, as digests (``cosim.logs.digest``): the record of what a change
must not alter. ``tests/test_golden_states.py`` compares every run with
``tests/data/golden_states.json``.

    python benchmarks/golden_states.py            # check against the record
    python benchmarks/golden_states.py --record   # write the record anew

Record anew only for a change meant to alter behaviour, and say so in its
commit. A record names the jsbsim and numpy versions, the machine and the
SIMD extensions numpy dispatches to on it (its vectorised sin, cos, hypot
and arctan2 differ in the last bit between AVX2 and AVX-512): floating point
differs elsewhere, so the file keeps one record per environment, and the
test skips where none matches. To add the AVX2 record on an AVX-512 machine:

    NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR" \
        python benchmarks/golden_states.py --record
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


#: what must match for a record to apply (python is informative only)
MATCH = ("jsbsim", "numpy", "machine", "simd")


def environment() -> dict[str, str]:
    import jsbsim
    import numpy
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    simd = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    return {"jsbsim": jsbsim.__version__, "numpy": numpy.__version__,
            "machine": platform.machine(), "python": platform.python_version()[:4],
            "simd": " ".join(simd)}


def records() -> list[dict[str, Any]]:
    """Every record in the file: ``{"environment": ..., "runs": ...}``."""
    if not RECORD.exists():
        return []
    return list(json.loads(RECORD.read_text())["records"])


def matching(env: dict[str, str]) -> dict[str, Any] | None:
    """The record made in an environment like ``env`` (None: none was)."""
    for r in records():
        if all(r["environment"].get(k) == env[k] for k in MATCH):
            return r
    return None


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
    env = environment()
    if a.record:
        others = [r for r in records()
                  if any(r["environment"].get(k) != env[k] for k in MATCH)]
        RECORD.parent.mkdir(parents=True, exist_ok=True)
        RECORD.write_text(json.dumps({"records": others + [{"environment": env, "runs": got}]},
                                     indent=1, sort_keys=True) + "\n")
        print(f"recorded {len(got)} scenarios in {RECORD} for {env}")
        return 0
    rec = matching(env)
    if rec is None:
        print(f"no record for {env}: record one with --record", file=sys.stderr)
        return 1
    want = rec["runs"]
    bad = [k for k in sorted(set(want) | set(got)) if want.get(k) != got.get(k)]
    for k in bad:
        print(f"DIFFERENT: {k}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
