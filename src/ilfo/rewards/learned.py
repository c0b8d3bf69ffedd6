"""Rewards that learn during training: the ``LearnedReward`` protocol and the expert data they see.

An episode reward (``EpisodeReward``: OOPS, PWIL) is computed once per learner episode, in numpy,
and written into the replay buffer. A learned reward (a discriminator, a reward network) changes
while the agent learns, so rewards frozen in the buffer would go stale: instead the agent's
jitted update asks it for the rewards of each sampled batch, with its current parameters
(``ilfo.composition.learned`` composes the two). Everything here is pure JAX: the reward's state
is a pytree (parameters, optimiser state, statistics) that is checkpointed with the agent's.

Observations given to a learned reward are the environment's (no time feature).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple, Protocol

import jax
import jax.numpy as jnp
import numpy as np

from ilfo.replay import ReplayData, sample_batch
from ilfo.rewards.base import check_demo_types, check_demos


class Transitions(NamedTuple):
    """A batch of state transitions (s, s'): what a state-only reward sees of either side."""

    obs: jax.Array
    """(B, obs_dim) s_t."""
    next_obs: jax.Array
    """(B, obs_dim) s_t+1."""


def expert_transitions(demos: Sequence[np.ndarray], min_count: int = 1) -> Transitions:
    """All transitions (s_t, s_t+1) of the demos (each (T_i + 1, obs_dim)), pooled.

    One demo may come as a 2-D array, as the episode rewards take it. Raises a ValueError where
    they hold fewer than ``min_count`` transitions (a batch size), a demo has fewer than two
    observations (no transition) or NaN or inf, or the demos' observation dimensions differ.
    """
    check_demo_types(demos)  # a file name or a DemoFile: say what to pass
    if isinstance(demos, np.ndarray) and demos.ndim == 2:
        demos = [demos]  # one demo, as check_demos takes it
    if len(demos) == 0:
        raise ValueError("a learned reward needs at least one demonstration")
    for i, demo in enumerate(demos):
        if np.ndim(demo) != 2 or len(demo) < 2:
            raise ValueError(
                f"demo {i} has shape {np.shape(demo)}: a learned reward needs (s, s') "
                "transitions, i.e. at least two observations of shape (T + 1, obs_dim)"
            )
    demos = check_demos(demos)  # finite, and one observation dimension
    obs = np.concatenate([np.asarray(d[:-1], np.float32) for d in demos])
    next_obs = np.concatenate([np.asarray(d[1:], np.float32) for d in demos])
    if len(obs) < min_count:
        raise ValueError(
            f"the demos hold {len(obs)} transitions, fewer than a batch of {min_count}: pass "
            "more demos (--num-demos) or a smaller batch size"
        )
    return Transitions(jnp.asarray(obs), jnp.asarray(next_obs))


def sample_transitions(data: Transitions, key: jax.Array, batch_size: int) -> Transitions:
    """``batch_size`` transitions of ``data`` drawn uniformly with replacement (jittable)."""
    idx = jax.random.randint(key, (batch_size,), 0, data.obs.shape[0])
    return Transitions(data.obs[idx], data.next_obs[idx])


class LearnedReward(Protocol):
    """A reward r(s, s') learned from expert and learner transitions, in pure JAX.

    ``init``, ``update`` and ``reward`` are pure functions of their arguments (jittable; the
    config is closed over), so the reward can be updated and queried inside the agent's
    jitted update."""

    batch_size: int
    """Expert and learner transitions per ``update``."""

    def init(self, key: jax.Array, expert: Transitions) -> Any:
        """Fresh state (a pytree); may read the expert transitions (e.g. input statistics)."""
        ...

    def update(
        self, state: Any, learner: Transitions, expert: Transitions, key: jax.Array
    ) -> tuple[Any, dict[str, jax.Array]]:
        """One gradient step on a batch of each; returns the new state and scalar metrics
        (``reward_loss``, and any others)."""
        ...

    def reward(self, state: Any, obs: jax.Array, next_obs: jax.Array) -> jax.Array:
        """Rewards (B,) of transitions obs, next_obs (B, obs_dim) under ``state``."""
        ...


class RolloutLearnedReward(Protocol):
    """A learned reward that learns from fresh episodes of the policy (f-IRL) rather than by
    ``update`` on replay batches: its part has a ``rollouts`` plan and no schedule.
    ``batch_size``, ``init`` and ``reward`` are ``LearnedReward``'s."""

    batch_size: int

    def init(self, key: jax.Array, expert: Transitions) -> Any: ...

    def reward(self, state: Any, obs: jax.Array, next_obs: jax.Array) -> jax.Array: ...

    def update_from_rollouts(
        self, state: Any, agent_trajs: jax.Array, expert_trajs: jax.Array, key: jax.Array
    ) -> tuple[Any, dict[str, jax.Array]]:
        """One learning step from the policy's episodes and the expert's, both (n, T, obs_dim);
        returns the new state and scalar metrics."""
        ...


class RewardSchedule(NamedTuple):
    """When the reward learns: ``steps`` gradient steps each time the agent's update count
    crosses a multiple of ``every`` (taken before the agent's updates of that call)."""

    every: int
    steps: int

    def steps_due(self, updates_done: int, num_updates: int) -> int:
        """Reward steps due before agent updates updates_done + 1 ... + num_updates."""
        crossed = (updates_done + num_updates) // self.every - updates_done // self.every
        return self.steps * crossed


def env_observations(obs: jax.Array, time_feature: bool) -> jax.Array:
    """The environment's part of agent observations: the time feature, where the run appends
    one, dropped (a reward of states must not see the clock)."""
    return obs[..., :-1] if time_feature else obs


def reward_steps(
    reward: LearnedReward,
    time_feature: bool,
    state: Any,
    data: ReplayData,
    size: jax.Array | int,
    expert: Transitions,
    num_steps: int,
) -> tuple[Any, dict[str, jax.Array]]:
    """``num_steps`` gradient steps of the reward, each on uniform draws of ``reward.batch_size``
    replay transitions and as many expert ones; metrics averaged over the steps. ``state`` is
    any pytree with fields ``reward`` (the reward's state) and ``key``."""

    def body(reward_state: Any, key: jax.Array):
        k_learner, k_expert, k_step = jax.random.split(key, 3)
        batch = sample_batch(data, size, k_learner, reward.batch_size)
        learner = Transitions(
            env_observations(batch.obs, time_feature),
            env_observations(batch.next_obs, time_feature),
        )
        expert_batch = sample_transitions(expert, k_expert, reward.batch_size)
        return reward.update(reward_state, learner, expert_batch, k_step)

    key, k_steps = jax.random.split(state.key)
    reward_state, metrics = jax.lax.scan(body, state.reward, jax.random.split(k_steps, num_steps))
    state = state.replace(reward=reward_state, key=key)
    return state, jax.tree.map(jnp.mean, metrics)
