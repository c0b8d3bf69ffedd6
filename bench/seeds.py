"""Benchmark: K seeds trained in one process, the agents' updates vmapped over seeds, against K
one-seed updates, on one core (issue 57's throughput question).

What is timed, for TD3's fast preset at Hopper's and Ant's sizes:
- ``update``: one jitted call of N updates of one agent (``make_td3(...).update``);
- ``vmapped``: one jitted call of N updates of K agents at once (``jax.vmap`` of the same update
  over K states and K replay buffers), per seed;
- ``env``: one environment step with the policy acting (``act`` on one observation), the part of
  a step that a vmapped update does not touch (gymnasium steps each seed's env on its own).

From these, the aggregate environment steps per second of one core running K seeds:
K / (K * env + time of K vmapped updates), against one seed per process (1 / (env + update)).
A gain of 1.5x or more would justify building K-seed runs into ``ilfo sweep``.

    taskset -c 0 python bench/seeds.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from datetime import date
from pathlib import Path

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np

sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.agents.td3 import TD3Config, make_td3
from ilfo.benchmarking import machine
from ilfo.replay import ReplayData

ENVS = {"hopper": ("Hopper-v5", {}), "ant": ("Ant-v5", {"include_cfrc_ext_in_observation": False})}


def _replay(size: int, obs_dim: int, action_dim: int, seed: int) -> ReplayData:
    rng = np.random.default_rng(seed)
    obs = rng.standard_normal((size, obs_dim), dtype=np.float32)
    obs[:, -1] = rng.integers(1, 1001, size) / 1000
    next_obs = rng.standard_normal((size, obs_dim), dtype=np.float32)
    next_obs[:, -1] = np.maximum(obs[:, -1] - 1e-3, 0.0)
    return ReplayData(
        obs=jnp.asarray(obs),
        action=jnp.asarray(rng.uniform(-1, 1, (size, action_dim)).astype(np.float32)),
        reward=jnp.asarray(rng.standard_normal(size, dtype=np.float32)),
        next_obs=jnp.asarray(next_obs),
        not_done=jnp.ones(size, jnp.float32),
    )


def _best(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def time_updates(obs_dim: int, action_dim: int, seeds: int, n: int, repeat: int) -> float:
    """Seconds per update per seed of ``seeds`` agents updated together (1: one agent)."""
    agent = make_td3(TD3Config.fast(), obs_dim, action_dim)
    size = 50_000

    # The seeds run in lockstep, so the update count (which picks grouped or one-by-one
    # updates for the policy delay) is shared: passed unbatched, it keeps vmap from turning
    # that choice into a select that runs both.
    def updates(state, data):
        return agent.run_updates(agent.update_step, state, data, size, n, 0)

    if seeds == 1:
        state, data = agent.init(0), _replay(size, obs_dim, action_dim, 0)
        update = jax.jit(updates)

        def run():
            jax.block_until_ready(update(state, data))

    else:
        states = jax.vmap(agent.init)(jnp.arange(seeds))
        datas = jax.tree.map(
            lambda *xs: jnp.stack(xs),
            *[_replay(size, obs_dim, action_dim, s) for s in range(seeds)],
        )
        update = jax.jit(jax.vmap(updates))

        def run():
            jax.block_until_ready(update(states, datas))

    return _best(run, repeat) / (n * seeds)


def time_env_step(env: gym.Env, obs_dim: int, action_dim: int, steps: int) -> float:
    """Seconds per environment step with the policy acting (one observation at a time)."""
    agent = make_td3(TD3Config.fast(), obs_dim, action_dim)
    state = agent.init(0)
    obs, _ = env.reset(seed=0)
    key = jax.random.PRNGKey(0)
    features = np.zeros(obs_dim, np.float32)
    start = time.perf_counter()
    for t in range(steps):
        features[:-1], features[-1] = obs[: obs_dim - 1], 1.0 - t / steps
        action = np.asarray(agent.act(state, features, jax.random.fold_in(key, t)))
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()
    return (time.perf_counter() - start) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 4, 8])
    args = parser.parse_args()
    n, repeat, env_steps = (50, 1, 500) if args.quick else (250, 3, 3000)
    print(f"# {date.today().isoformat()}, {machine(jax=jax.__version__)}")
    print("| env | seeds K | update ms/seed | env+act ms | steps/s of one core | vs K = 1 |")
    print("|---|---|---|---|---|---|")
    for name, (env_id, kwargs) in ENVS.items():
        env = gym.make(env_id, **kwargs)
        obs_dim = int(np.prod(env.observation_space.shape)) + 1
        action_dim = int(np.prod(env.action_space.shape))
        env_s = time_env_step(env, obs_dim, action_dim, env_steps)
        base = None
        for k in args.seeds:
            upd = time_updates(obs_dim, action_dim, k, n, repeat)
            rate = 1.0 / (env_s + upd)
            base = rate if base is None else base
            print(
                f"| {name} | {k} | {1e3 * upd:.3f} | {1e3 * env_s:.3f} | {rate:.0f} "
                f"| {rate / base:.2f}x |"
            )


if __name__ == "__main__":
    main()
