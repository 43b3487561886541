"""cosim's pool against what a reinforcement-learning user would otherwise
write: gymnasium's ``AsyncVectorEnv`` with one JSBSim aircraft per
environment (one subprocess each), measured side by side (``cosim bench
--gym``, ``benchmarks/gym_reference.py``; gymnasium comes with the ``rl``
extra).

Both step N uav700s (built and trimmed by cosim, at 1000 m, 100 kt) through
the same simulated time at the bench's physics rate with an exchange (an
``env.step`` for gymnasium, a pool exchange for cosim) every ``every``
ticks, reading every aircraft's state row back each time; the aircraft-steps
per second of each, in interleaved rounds, and their ratio.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from cosim.errors import ConfigError, install_extra


def require_gymnasium() -> Any:
    try:
        import gymnasium
    except ImportError:
        raise ConfigError(f"the gymnasium reference needs gymnasium: {install_extra('rl')}"
                          ) from None
    return gymnasium


def _make(index: int, n: int, dt_s: float, every: int) -> Callable[[], Any]:
    """An environment holding aircraft ``index`` of the bench's fleet of ``n``."""
    def make() -> Any:
        gym = require_gymnasium()
        from cosim.bench.fleet import bench_specs
        from cosim.fdm_pool.shard import Shard

        env: Any = gym.Env

        class OneAircraft(env):
            """One cosim-built uav700 (its FDM trimmed by cosim); an action is
            ignored (it flies its trim), a step is ``every`` physics ticks,
            the observation its state row."""

            def __init__(self) -> None:
                spec = bench_specs(n, "uav700")[index]
                self.shard = Shard.build([spec], dt_s, ())
                self.out = np.zeros((1, self.shard.n_columns))
                self.observation_space = gym.spaces.Box(-np.inf, np.inf,
                                                        (self.shard.n_columns,), np.float64)
                self.action_space = gym.spaces.Box(0.0, 1.0, (1,), np.float64)

            def reset(self, *, seed: int | None = None, options: Any = None
                      ) -> tuple[np.ndarray, dict[str, Any]]:
                self.shard.write_states(self.out)
                return self.out[0].copy(), {}

            def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
                self.shard.exchange(None, every, self.out)
                return self.out[0].copy(), 0.0, False, False, {}

        return OneAircraft()

    return make


def _steps_per_s(step: Callable[[], Any], n: int, ticks: int, every: int) -> float:
    exchanges = max(1, ticks // every)
    t0 = time.perf_counter()
    for _ in range(exchanges):
        step()
    return n * exchanges * every / (time.perf_counter() - t0)


def gym_rate(n: int, ticks: int, every: int, dt_s: float) -> float:
    """AsyncVectorEnv (shared memory), one aircraft per environment."""
    from gymnasium.vector import AsyncVectorEnv

    envs = AsyncVectorEnv([_make(i, n, dt_s, every) for i in range(n)], shared_memory=True)
    try:
        envs.reset(seed=0)
        actions = np.zeros((n, 1))
        return _steps_per_s(lambda: envs.step(actions), n, ticks, every)
    finally:
        envs.close()


def pool_rate(n: int, ticks: int, every: int, dt_s: float, backend: str = "process",
              workers: int | None = None) -> float:
    from cosim.bench.fleet import bench_specs
    from cosim.fdm_pool import make_pool

    with make_pool(bench_specs(n, "uav700"), dt_s, (), backend, workers) as pool:
        pool.step(every)
        return _steps_per_s(lambda: pool.step(every), n, ticks, every)


def compare(n: int, seconds: float, rounds: int, physics_hz: float = 120.0, every: int = 4,
            backend: str = "process", workers: int | None = None) -> dict[str, Any]:
    """gymnasium and the pool at ``n`` aircraft, ``rounds`` interleaved rounds."""
    require_gymnasium()
    dt_s, ticks = 1.0 / physics_hz, int(seconds * physics_hz)
    g, p = [], []
    for _ in range(rounds):  # interleaved: the same machine load for both
        g.append(gym_rate(n, ticks, every, dt_s))
        p.append(pool_rate(n, ticks, every, dt_s, backend, workers))
    return {"vehicles": n, "gym_steps_per_s": statistics.median(g),
            "pool_steps_per_s": statistics.median(p),
            "pool_over_gym": statistics.median([y / x for x, y in zip(g, p)]),
            "gym_all": g, "pool_all": p}
