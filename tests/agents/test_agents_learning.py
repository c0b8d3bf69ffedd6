"""Learning smoke tests: TD3 and TD7 (fast presets) and SAC solve Pendulum-v1 (slow; ``-m slow``).

The loop mirrors the paper's: random steps first, then the policy is frozen during an episode,
the episode enters the buffer whole, and as many updates run as steps were collected.
"""

from __future__ import annotations

import time

import gymnasium as gym
import jax
import numpy as np
import pytest

from ilfo.agents import SACConfig, TD3Config, make_sac, make_td3
from ilfo.agents.td7 import TD7Config, make_td7
from ilfo.replay import ReplayBuffer

TOTAL_STEPS = 15_000
RANDOM_STEPS = 1_000


def train_and_evaluate(agent, seed: int = 0) -> tuple[float, float]:
    """Return (mean deterministic return over 10 episodes, training seconds)."""
    env = gym.make("Pendulum-v1")
    max_action = float(env.action_space.high[0])
    state = agent.init(seed)
    buf = ReplayBuffer(TOTAL_STEPS, env.observation_space.shape[0], env.action_space.shape[0])
    key = jax.random.PRNGKey(seed + 1)
    rng = np.random.default_rng(seed)
    steps, episode = 0, 0
    start = time.perf_counter()
    while steps < TOTAL_STEPS:
        obs, _ = env.reset(seed=seed + episode)
        episode += 1
        observations, actions, rewards = [obs], [], []
        terminated = truncated = False
        while not (terminated or truncated):
            if steps < RANDOM_STEPS:
                action = rng.uniform(-max_action, max_action, size=1).astype(np.float32)
            else:
                key, k = jax.random.split(key)
                action = np.asarray(agent.act(state, obs, k))
            obs, reward, terminated, truncated, _ = env.step(action)
            observations.append(obs)
            actions.append(action)
            rewards.append(reward)
            steps += 1
        buf.add_episode(np.stack(observations), np.stack(actions), rewards, terminated)
        if steps >= RANDOM_STEPS:
            state, _ = agent.update(state, buf.data, buf.size, num_updates=len(actions))
    seconds = time.perf_counter() - start

    returns = []
    for i in range(10):
        obs, _ = env.reset(seed=10_000 + i)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(np.asarray(agent.act(state, obs)))
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns)), seconds


@pytest.mark.slow
@pytest.mark.parametrize("name", ["td3_fast", "td3_fast_layer_norm", "td7_fast", "sac"])
def test_learns_pendulum(name):
    # Pendulum has no fixed 1000-step horizon, hence no time feature.
    if name == "td3_fast":
        agent = make_td3(TD3Config.fast(time_augmentation=False), 3, 1, 2.0)
    elif name == "td3_fast_layer_norm":
        config = TD3Config.fast(time_augmentation=False, critic_layer_norm=True)
        agent = make_td3(config, 3, 1, 2.0)
    elif name == "td7_fast":
        agent = make_td7(TD7Config.fast(time_augmentation=False), 3, 1, 2.0)
    else:
        agent = make_sac(SACConfig(), 3, 1, 2.0)
    mean_return, seconds = train_and_evaluate(agent)
    print(f"{name}: mean return {mean_return:.1f} after {TOTAL_STEPS} steps, {seconds:.0f} s")
    assert mean_return > -400
