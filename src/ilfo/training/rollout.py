"""Episodes of a policy, and the one home of the time feature.

Fixed-horizon runs append the time feature, remaining_steps / horizon
(``ilfo.envs.time_feature``), to each observation the agent sees (the paper's code);
``agent_observation`` (one step) and ``agent_observations`` (a whole episode) are what the loop,
evaluation, experts and bench scripts call, and ``ilfo.envs.TimeFeature`` gives the same
observations to other people's RL code.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from ilfo import envs
from ilfo.agents import policy_of
from ilfo.envs import episode_scores
from ilfo.training.build import Agent, agent_observations


def agent_observation(obs: np.ndarray, t: int, horizon: int, time_feature: bool) -> np.ndarray:
    """What the agent sees at step ``t`` of an episode: ``obs``, with (horizon - t) / horizon
    appended where ``time_feature``; float32."""
    if time_feature:
        return np.append(obs, envs.time_feature(t, horizon)).astype(np.float32)
    return np.asarray(obs, dtype=np.float32)


def env_action(action: np.ndarray, max_action: float) -> np.ndarray:
    """What the environment is sent for ``action``: float64, clipped to [-max_action,
    max_action]. Off-policy agents act within the box already (unchanged); TRPO's Gaussian
    actions are unbounded, as in SIL's code, and are learned from as drawn."""
    return np.clip(np.asarray(action, np.float64), -max_action, max_action)


def policy_actions(agent: Agent, policy: Any, observations: np.ndarray, horizon: int) -> np.ndarray:
    """The deterministic actions (T, a) a policy takes along an episode's observations
    (T + 1, d) (its last observation has no action)."""
    obs = agent_observations(observations[:-1], horizon, agent.time_feature)
    return np.asarray(agent.functions.act(policy_of(policy), obs.astype(np.float32)))


class Rollout(NamedTuple):
    """One evaluation episode: observations (T + 1, d), task rewards (T,), terminations (T,),
    rendered frames (empty unless asked for) and the actions taken (T, a)."""

    observations: np.ndarray
    rewards: np.ndarray
    env_terminated: np.ndarray
    frames: list[np.ndarray]
    actions: np.ndarray


def rollout_policy(
    env: Any,
    agent: Agent,
    state: Any,
    horizon: int,
    seed: int,
    render: bool = False,
    key: Any = None,
    observe: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Rollout:
    """A fixed-horizon episode of the agent's policy (``state``: an agent state or a
    ``Policy``): deterministic, or with the policy's exploration where ``key`` (a JAX key) is
    given (step t's key: ``jax.random.fold_in(key, t)``). ``observe``: what the policy sees of
    each of ``env``'s observations, where it sees less than the rollout records (an expert
    without the contact forces, acting in the full env: ``ExpertPolicy.observe``)."""
    import jax

    policy = policy_of(state)
    obs, _ = env.reset(seed=seed)
    observations, rewards, terminated_flags, actions = [obs], [], [], []
    frames = []
    step_keys = None if key is None else np.asarray(jax.random.split(key, horizon))
    for t in range(horizon):
        seen = obs if observe is None else observe(obs)
        agent_obs = agent_observation(seen, t, horizon, agent.time_feature)
        if step_keys is None:
            action = np.asarray(agent.functions.act(policy, agent_obs))
        else:
            action = np.asarray(agent.functions.act(policy, agent_obs, step_keys[t]))
        obs, reward, terminated, truncated, info = env.step(
            env_action(action, agent.functions.max_action)
        )
        actions.append(action)
        if render:
            frames.append(env.render())
        observations.append(obs)
        rewards.append(float(reward))
        terminated_flags.append(bool(info.get("env_terminated", terminated)))
        if terminated or truncated:
            break
    return Rollout(
        np.asarray(observations),
        np.asarray(rewards),
        np.asarray(terminated_flags),
        frames,
        np.asarray(actions, dtype=np.float32).reshape(len(actions), -1),
    )


class PolicyScores(NamedTuple):
    """Scores of deterministic fixed-horizon episodes, one entry per episode."""

    scores: np.ndarray
    """The paper's fixed-horizon score (rewards of steps with a reported fall zeroed)."""
    returns: np.ndarray
    """The standard return (up to and including the first fall)."""
    distances: np.ndarray
    """OT distance of each episode to the probe's demo; empty without a probe."""
    frames: list[np.ndarray]
    """Rendered frames of the first episode, if asked for."""


def evaluation_seeds(run_seed: int, episodes: int) -> list[int]:
    """The seeds of a run's evaluation episodes: the same at every evaluation (a curve compares
    policies, not starts), apart from the training episodes' and the demos' (0, 1, ...), and
    what ``ilfo eval`` uses, so that it scores a final policy as its last evaluation did."""
    return [10_000_019 * (run_seed + 1) + k for k in range(episodes)]


def score_policy(
    env: Any,
    agent: Agent,
    state: Any,
    horizon: int,
    seeds: list[int],
    distance_probe: Any = None,
    render_first: bool = False,
) -> PolicyScores:
    """Roll out the deterministic policy once per seed and score each episode."""
    scores, returns, distances, frames = [], [], [], []
    for k, seed in enumerate(seeds):
        rollout = rollout_policy(
            env, agent, state, horizon, seed=seed, render=render_first and k == 0
        )
        frames.extend(rollout.frames)
        fixed, standard = episode_scores(rollout.rewards, rollout.env_terminated)
        scores.append(fixed)
        returns.append(standard)
        if distance_probe is not None:
            distances.append(distance_probe(rollout.observations).distance)
    return PolicyScores(np.array(scores), np.array(returns), np.array(distances), frames)
