"""Helpers shared by the agent tests: tiny networks and a small random replay buffer."""

from __future__ import annotations

import numpy as np

from ilfo.replay import ReplayBuffer

OBS_DIM, ACT_DIM, MAX_ACTION = 4, 2, 2.0
TINY = {"actor_hidden": (16, 16), "critic_hidden": (16, 16), "batch_size": 8}


def random_buffer(
    seed: int = 0, episodes: int = 3, length: int = 20, obs_dim: int = OBS_DIM
) -> ReplayBuffer:
    """A buffer with ``episodes`` random episodes; rewards are a fixed function of (s, a)."""
    rng = np.random.default_rng(seed)
    buf = ReplayBuffer(capacity=episodes * length + 7, obs_dim=obs_dim, action_dim=ACT_DIM)
    for _ in range(episodes):
        obs = rng.normal(size=(length + 1, obs_dim)).astype(np.float32)
        if obs_dim > 1:
            obs[:, -1] = (length - np.arange(length + 1)) / 1000.0  # a time feature
        act = rng.uniform(-MAX_ACTION, MAX_ACTION, size=(length, ACT_DIM)).astype(np.float32)
        rew = np.sin(obs[:-1, 0]) + 0.5 * act[:, 0]
        buf.add_episode(obs, act, rew)
    return buf
