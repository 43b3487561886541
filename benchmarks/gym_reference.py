"""cosim's pool against what a reinforcement-learning user would otherwise
write: gymnasium's ``AsyncVectorEnv`` with one JSBSim aircraft per
environment (one subprocess each), measured side by side in one run.

Both step N uav700s (built and trimmed by cosim, at 1000 m, 100 kt) through
the same simulated time at 120 Hz physics with an exchange (an ``env.step``
for gymnasium, a pool exchange for cosim) at 30 Hz, reading every aircraft's
state row back each time; for each N, in interleaved rounds, the
aircraft-steps per second of each and their ratio.

    pip install -e '.[rl]'
    python benchmarks/gym_reference.py --vehicles 16,64
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

PHYSICS_HZ = 120.0
EVERY = 4  # physics ticks per exchange: 30 Hz


try:
    import gymnasium as gym
except ImportError:  # main() says how to install it
    gym = None


class OneAircraft(gym.Env if gym is not None else object):  # type: ignore[misc]
    """A gymnasium environment holding one cosim-built uav700 (its FDM
    trimmed by cosim); an action is ignored (the aircraft flies its trim),
    a step is ``EVERY`` physics ticks, the observation its state row."""

    def __init__(self, index: int) -> None:
        from cosim.bench import bench_specs
        from cosim.fdm_pool.shard import Shard

        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (19,), np.float64)
        self.action_space = gym.spaces.Box(0.0, 1.0, (1,), np.float64)
        spec = bench_specs(index + 1, "uav700")[index]
        self.shard = Shard.build([spec], 1 / PHYSICS_HZ, ())
        self.out = np.zeros((1, self.shard.n_columns))

    def reset(self, *, seed: int | None = None, options: Any = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        self.shard.write_states(self.out)
        return self.out[0, :19].copy(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.shard.exchange(None, EVERY, self.out)
        return self.out[0, :19].copy(), 0.0, False, False, {}


def _make(index: int) -> Any:
    return lambda: OneAircraft(index)


def _steps_per_s(step: Callable[[], Any], n: int, seconds: float) -> float:
    """Aircraft-steps per second of ``step`` (one exchange of ``n`` aircraft)
    called for ``seconds`` of simulated time."""
    exchanges = int(seconds * PHYSICS_HZ) // EVERY
    t0 = time.perf_counter()
    for _ in range(exchanges):
        step()
    return n * exchanges * EVERY / (time.perf_counter() - t0)


def gym_rate(n: int, seconds: float) -> float:
    from gymnasium.vector import AsyncVectorEnv

    envs = AsyncVectorEnv([_make(i) for i in range(n)], shared_memory=True)
    try:
        envs.reset(seed=0)
        actions = np.zeros((n, 1))
        return _steps_per_s(lambda: envs.step(actions), n, seconds)
    finally:
        envs.close()


def pool_rate(n: int, seconds: float) -> float:
    from cosim.bench import bench_specs
    from cosim.fdm_pool import make_pool

    with make_pool(bench_specs(n, "uav700"), 1 / PHYSICS_HZ, (), "process", None) as pool:
        pool.step(EVERY)
        return _steps_per_s(lambda: pool.step(EVERY), n, seconds)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", default="16,64")
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated per round")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    if gym is None:
        print("gymnasium is not installed: pip install -e '.[rl]'", file=sys.stderr)
        return 2
    print("| aircraft | gymnasium AsyncVectorEnv (aircraft-steps/s) | cosim pool "
          "| cosim / gymnasium |")
    print("|---|---|---|---|")
    for n in [int(x) for x in a.vehicles.split(",")]:
        g, p = [], []
        for _ in range(a.rounds):  # interleaved: the same machine load for both
            g.append(gym_rate(n, a.seconds))
            p.append(pool_rate(n, a.seconds))
        gm, pm = statistics.median(g), statistics.median(p)
        ratio = statistics.median([y / x for x, y in zip(g, p)])
        print(f"| {n} | {gm:,.0f} | {pm:,.0f} | {ratio:.1f}x |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
