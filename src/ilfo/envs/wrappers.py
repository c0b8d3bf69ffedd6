"""The paper's fixed-horizon protocol as plain gymnasium wrappers, usable with any RL code.

- ``IgnoreTermination``: a reported termination becomes ``info["env_terminated"]`` and the
  episode goes on (``make_env(..., fixed_horizon=True)`` puts it inside the time limit).
- ``TimeFeature``: appends the remaining time (horizon - t) / horizon to each observation, as
  ilfo's agents see it in fixed-horizon runs (``time_feature`` is the formula's one home).
- ``FixedHorizonScore``: at an episode's last step, ``info`` gets the paper's fixed-horizon
  score (the rewards of steps reported as terminated count 0) and the standard return (up to
  and including the first termination), as ``episode_scores`` computes them for a whole
  episode.
"""

from __future__ import annotations

from typing import Any, SupportsFloat, overload

import gymnasium as gym
import numpy as np


@overload
def time_feature(t: int, horizon: int) -> float: ...
@overload
def time_feature(t: np.ndarray, horizon: int) -> np.ndarray: ...
def time_feature(t: int | np.ndarray, horizon: int) -> float | np.ndarray:
    """The time feature at step ``t`` (0 at the first observation) of a ``horizon``-step
    episode: the fraction of the episode still to go, 1 at the start and 0 at the end."""
    return (horizon - t) / horizon


def with_time_feature(observations: np.ndarray, horizon: int) -> np.ndarray:
    """A whole episode's observations (T + 1, d) with the time feature appended as a last
    column, as ``TimeFeature`` gives them one by one; the dtype of ``observations`` is kept."""
    remaining = time_feature(np.arange(len(observations)), horizon)
    return np.concatenate([observations, remaining[:, None]], axis=1)


class IgnoreTermination(gym.Wrapper):
    """Turns ``terminated`` into ``info["env_terminated"] = True`` so the episode goes on."""

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        info = dict(info)
        info["env_terminated"] = bool(terminated)
        return obs, reward, False, truncated, info


class TimeFeature(gym.ObservationWrapper):
    """Appends ``time_feature(t, horizon)`` to each (flat, Box) observation; ``horizon``
    defaults to the env's time limit."""

    def __init__(self, env: gym.Env, horizon: int | None = None) -> None:
        super().__init__(env)
        if horizon is None:
            horizon = env.spec.max_episode_steps if env.spec else None
        if horizon is None:
            raise ValueError("TimeFeature needs a horizon: pass one, or wrap a time-limited env")
        if horizon < 1:
            raise ValueError(f"TimeFeature's horizon must be >= 1, got {horizon}")
        space = env.observation_space
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ValueError(f"TimeFeature needs a flat Box observation space, got {space}")
        self.horizon = int(horizon)
        self.observation_space = gym.spaces.Box(
            np.append(space.low, 0.0).astype(space.dtype),
            np.append(space.high, 1.0).astype(space.dtype),
            dtype=space.dtype,
        )
        self._t = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self._t = 0
        return super().reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        self._t += 1
        return super().step(action)

    def observation(self, observation: Any) -> np.ndarray:
        feature = time_feature(self._t, self.horizon)
        return np.append(observation, feature).astype(self.observation_space.dtype)


class FixedHorizonScore(gym.Wrapper):
    """Adds ``info["fixed_horizon_score"]`` and ``info["standard_return"]`` at the last step of
    each episode (terminated or truncated); put it outside ``IgnoreTermination``, which it
    reads (``info["env_terminated"]``)."""

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self._rewards: list[float] = []
        self._terminated: list[bool] = []
        return self.env.reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._rewards.append(float(reward))
        self._terminated.append(bool(info.get("env_terminated", terminated)))
        if terminated or truncated:
            score, standard = episode_scores(np.array(self._rewards), np.array(self._terminated))
            info = {**info, "fixed_horizon_score": score, "standard_return": standard}
        return obs, reward, terminated, truncated, info


def episode_scores(rewards: np.ndarray, env_terminated: np.ndarray) -> tuple[float, float]:
    """Both scores of one fixed-horizon episode: (fixed-horizon score, standard return).

    The fixed-horizon score (the paper's) sums the task reward over the whole horizon with the
    reward of every step on which the environment reported termination set to 0. The standard
    return sums rewards up to and including the first termination, as a standard episode would.

    Args:
        rewards: Task rewards, shape (T,).
        env_terminated: Whether the environment reported termination at each step, shape (T,).
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    env_terminated = np.asarray(env_terminated, dtype=bool)
    fixed = float(np.where(env_terminated, 0.0, rewards).sum())
    hits = np.flatnonzero(env_terminated)
    end = hits[0] + 1 if hits.size else len(rewards)
    return fixed, float(rewards[:end].sum())
