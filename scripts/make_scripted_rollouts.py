"""Make data/demos/Hopper-v5-scripted.npz: Hopper-v5 rollouts of two simple scripted policies.

NOT expert data. These are real Hopper-v5 trajectories of fixed length 1,000 (termination ignored,
as in the paper's training) from (1) ``gait``: a fixed random linear feedback plus an open-loop
sine, 10 episodes, and (2) ``random``: uniform random actions, 2 episodes. They exist so that the
reward demo and the OT benchmark run on real trajectories before SAC experts are shipped.

    python scripts/make_scripted_rollouts.py
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from ilfo.demos import Episode, save

ENV_ID = "Hopper-v5"
HORIZON = 1000


def rollout(policy: str, seed: int) -> Episode:
    env = gym.make(ENV_ID, terminate_when_unhealthy=False, max_episode_steps=HORIZON)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    gain = np.random.default_rng(1).normal(0.0, 0.5, size=(3, obs.shape[0]))
    observations, actions, rewards = [obs], [], []
    for t in range(HORIZON):
        if policy == "gait":
            action = np.tanh(gain @ obs) + 0.3 * np.sin(0.1 * t + np.arange(3))
        else:
            action = rng.uniform(-1.0, 1.0, size=3)
        action = np.clip(action, -1.0, 1.0)
        obs, reward, _, _, _ = env.step(action)
        observations.append(obs)
        actions.append(action)
        rewards.append(reward)
    return Episode(np.array(observations), np.array(actions), np.array(rewards))


def main() -> None:
    episodes = [rollout("gait", seed) for seed in range(10)]
    episodes += [rollout("random", seed) for seed in (100, 101)]
    out = Path(__file__).resolve().parents[1] / "data" / "demos" / f"{ENV_ID}-scripted.npz"
    save(
        out,
        episodes,
        ENV_ID,
        provenance={
            "policies": ["gait"] * 10 + ["random"] * 2,
            "note": "scripted policies, not an expert; fixed horizon 1000",
            "script": "scripts/make_scripted_rollouts.py",
        },
    )
    print(f"wrote {out}: returns {[round(e.task_return) for e in episodes]}")


if __name__ == "__main__":
    main()
