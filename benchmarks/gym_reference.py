"""cosim's pool against what a reinforcement-learning user would otherwise
write: gymnasium's ``AsyncVectorEnv`` with one JSBSim aircraft per
environment (one subprocess each), measured side by side in one run
(``cosim.bench_gym``; ``cosim bench --gym`` does the same beside its own
table).

    pip install -e '.[rl]'
    python benchmarks/gym_reference.py --vehicles 16,64
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", default="16,64")
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated per round")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    from cosim.bench.gym import compare
    from cosim.errors import ConfigError

    print("| aircraft | gymnasium AsyncVectorEnv (aircraft-steps/s) | cosim pool "
          "| cosim / gymnasium |")
    print("|---|---|---|---|")
    for n in [int(x) for x in a.vehicles.split(",")]:
        try:
            r = compare(n, a.seconds, a.rounds)
        except ConfigError as e:
            print(e, file=sys.stderr)
            return 2
        print(f"| {n} | {r['gym_steps_per_s']:,.0f} | {r['pool_steps_per_s']:,.0f} | "
              f"{r['pool_over_gym']:.1f}x |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
