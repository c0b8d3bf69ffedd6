"""How well a run's critic knows its own policy's value: Q against the true return-to-go.

Loads the last checkpoint of an `ilfo train` run (TD3, DDPG or SAC), rolls its deterministic
policy out in the run's evaluation env, computes the rewards the run trains on for that episode
(its rewarder's, or the task reward), and prints at a few steps t the critics' value
min_i Q_i(s_t, pi(s_t)) beside the episode's discounted return-to-go G_t. Where observations
carry the time-to-go (fixed-horizon runs), it also prints the critic's value at the same state
and action with one step to go and with the whole horizon to go: a critic that has learnt the
finite horizon says about r_t with one step to go.

    python bench/critic.py RUN_DIR [--episodes 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import date
from pathlib import Path
from typing import Any

import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.benchmarking import machine
from ilfo.training import (
    Agent,
    agent_observations,
    load_demo_set,
    load_run_policy,
    make_envs,
    make_reward,
    rollout_policy,
)

PROBE_STEPS = (0, 50, 100, 200, 400, 700, 900, 990)


def return_to_go(rewards: np.ndarray, gamma: float) -> np.ndarray:
    """G_t = sum_{i >= t} gamma^(i - t) r_i for every t of one episode (no bootstrap at its end)."""
    out = np.zeros(len(rewards))
    acc = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        acc = rewards[t] + gamma * acc
        out[t] = acc
    return out


def min_q(agent: Agent, state: Any, obs: np.ndarray, action: Any) -> np.ndarray:
    """min_i Q_i(obs, action) of the agent's online critics, in float64."""
    values = agent.functions.q_values(state, obs, action)
    return np.asarray(values, dtype=np.float64).min(axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run_dir", help="an `ilfo train` run directory with a checkpoint")
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--first-seed", type=int, default=10_000)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.episodes < 1:
        parser.error(f"--episodes must be >= 1, got {args.episodes}")

    run = load_run_policy(args.run_dir, "latest")  # the whole agent state: critics too
    assert run.checkpoint is not None
    agent, state, horizon = run.agent, run.checkpoint.agent_state, run.env.horizon
    _, eval_env, _ = make_envs(run.config)
    reward = make_reward(run.config, load_demo_set(run.config, run.env.obs_dim).observations)
    gamma = agent.functions.config.gamma
    meta = {
        "run": str(args.run_dir),
        "step": run.checkpoint.step,
        "date": date.today().isoformat(),
        "machine": machine(),
    }
    for k in range(args.episodes):
        rollout = rollout_policy(eval_env, agent, state, horizon, seed=args.first_seed + k)
        obs = agent_observations(rollout.observations[:-1], horizon, agent.time_feature)
        if reward is not None:
            rewards = np.asarray(reward(rollout.observations).rewards)
        else:
            rewards = rollout.rewards
        g = return_to_go(rewards, gamma)
        steps = [t for t in PROBE_STEPS if t < len(obs)]
        x = obs[steps].astype(np.float32)
        action = agent.functions.act(state, x)
        q = min_q(agent, state, x, action)
        row: dict = {
            "bench": "critic",
            **meta,
            "episode": k,
            "episode_reward": float(rewards.sum()),
            "t": steps,
            "q": q.round(2).tolist(),
            "return_to_go": g[steps].round(2).tolist(),
            "reward": rewards[steps].round(2).tolist(),
        }
        if agent.time_feature:
            one, full = x.copy(), x.copy()
            one[:, -1], full[:, -1] = 1.0 / horizon, 1.0
            row["q_one_step_to_go"] = min_q(agent, state, one, action).round(2).tolist()
            row["q_horizon_to_go"] = min_q(agent, state, full, action).round(2).tolist()
        if args.json:
            print(json.dumps(row))
            continue
        print(
            f"{args.run_dir} at step {run.checkpoint.step}, episode {k}: reward {rewards.sum():.0f}"
        )
        print(
            "      t        Q      G_t"
            + ("   Q(k=1)      r_t  Q(k=H)" if agent.time_feature else "")
        )
        for i, t in enumerate(steps):
            line = f"{t:7d} {q[i]:8.1f} {g[t]:8.1f}"
            if agent.time_feature:
                q_one, q_full = row["q_one_step_to_go"][i], row["q_horizon_to_go"][i]
                line += f" {q_one:8.1f} {rewards[t]:8.2f} {q_full:7.1f}"
            print(line)


if __name__ == "__main__":
    main()
