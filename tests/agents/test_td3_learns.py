"""TD3 learns: ``ilfo train --algo td3`` on Pendulum-v1 (the task reward), 8,000 steps through
the whole loop (it starts to swing up at about 6,000), beats a uniformly random policy by
far. The CI's check that an agent learns at all; the longer per-agent learning tests are ``-m slow``
(``tests/agents/test_agents_learning.py``)."""

from __future__ import annotations

import csv

import gymnasium as gym
import numpy as np
import pytest

from ilfo.training import TrainConfig, Trainer

pytestmark = pytest.mark.integration

STEPS = 8_000
EPISODES = 5


def _random_return() -> float:
    """Mean return of uniformly random actions over EPISODES episodes."""
    env = gym.make("Pendulum-v1")
    env.action_space.seed(0)
    returns = []
    for seed in range(EPISODES):
        env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def test_td3_on_pendulum_beats_a_random_policy_by_far(tmp_path):
    config = TrainConfig(
        env="Pendulum-v1",
        algo="td3",
        preset="fast",
        steps=STEPS,
        start_steps=1_000,
        eval_every=STEPS,
        eval_episodes=EPISODES,
        checkpoint_every=STEPS,
        replay_capacity=STEPS,
    )
    run = Trainer(config, tmp_path / "run", progress=False).train()
    with (run / "metrics.csv").open() as f:
        final = [float(row["eval_return"]) for row in csv.DictReader(f) if row["eval_return"]]
    random = _random_return()
    # Returns are costs (<= 0): the trained policy must have shed more than half of a random
    # policy's (about -1200), which it does only once it swings the pendulum up and holds it.
    assert final[-1] > 0.5 * random, (final, random)
