"""An off-policy agent trained on a learned reward: TD3 or SAC whose batches are rewarded by a
``LearnedReward`` (a discriminator) with its current parameters, the reward trained beside it.

``with_learned_reward`` composes the two into one agent with the loop's ``AgentFunctions``
interface, so the training loop, checkpoints, resume and evaluation treat it as any agent: its
state (``LearnedRewardState``) holds the agent's state and the reward's, and its ``update``
first takes the reward's gradient steps that fall due (``RewardSchedule``), then the agent's
updates, each on a replay batch whose stored rewards are replaced by the reward's, computed
inside the jitted update (no relabelling of the buffer; nothing stale).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, NamedTuple, cast

import flax
import jax
import jax.numpy as jnp
from numpy.typing import ArrayLike

from ilfo.agents.sac import SAC
from ilfo.agents.td3 import TD3
from ilfo.replay import ReplayData
from ilfo.rewards.learned import (
    LearnedReward,
    RewardSchedule,
    RolloutLearnedReward,
    Transitions,
    env_observations,
    reward_steps,
)


class RolloutPlan(NamedTuple):
    """For a reward that learns from fresh episodes of the current policy (f-IRL): every
    ``every`` environment steps, the loop collects ``episodes`` stochastic fixed-horizon
    episodes (not stored, not counted as training steps) and passes their states s_1..s_T to
    ``learn_from_rollouts``."""

    every: int
    episodes: int


class LearnedRewardState(flax.struct.PyTreeNode):
    """The composed agent's state (a pytree): the agent's, the reward's, and a key for drawing
    batches. Reads like an agent state where the loop needs one (the policy, the normaliser)."""

    agent: Any
    reward: Any
    updates: jax.Array
    """() int32, agent updates done (what the reward's schedule counts)."""
    key: jax.Array

    @property
    def actor_params(self) -> Any:
        return self.agent.actor_params

    @property
    def obs_mean(self) -> jax.Array:
        return self.agent.obs_mean

    @property
    def obs_std(self) -> jax.Array:
        return self.agent.obs_std

    @property
    def normalizer_set(self) -> jax.Array:
        return self.agent.normalizer_set


class LearnedRewardAgent(NamedTuple):
    """``AgentFunctions`` of an agent with a learned reward, plus the reward of transitions."""

    obs_dim: int
    action_dim: int
    max_action: float
    init: Callable[[int], LearnedRewardState]
    act: Callable[..., jax.Array]
    update: Callable[..., tuple[LearnedRewardState, dict[str, jax.Array]]]
    """update(state, data, size, num_updates) -> (state, metrics): the reward's steps that
    are due, then ``num_updates`` agent updates (metrics of both)."""
    set_normalizer: Callable[[LearnedRewardState, ArrayLike, ArrayLike], LearnedRewardState]
    q_values: Callable[[LearnedRewardState, jax.Array, jax.Array], jax.Array]
    rewards: Callable[[LearnedRewardState, jax.Array, jax.Array], jax.Array]
    """rewards(state, obs, next_obs) -> (B,): the reward's current values of environment
    transitions (no time feature), for logging an episode's proxy return."""
    rollouts: RolloutPlan | None = None
    """Where the reward learns from fresh episodes of the policy: when, and how many."""
    learn_from_rollouts: Callable[..., tuple[LearnedRewardState, dict[str, jax.Array]]] | None = (
        None
    )
    """learn_from_rollouts(state, trajectories (n, T, obs_dim)) -> (state, metrics): the
    reward's learning from the policy's episodes (their states s_1..s_T) and the expert's."""


class LearnedRewardSetup(NamedTuple):
    """What an agent trained on a learned reward is built with (``ilfo.training.build``)."""

    reward: LearnedReward | RolloutLearnedReward
    schedule: RewardSchedule | None
    """When the reward takes its gradient steps on replay and expert batches; None: never
    (a reward that learns from rollouts)."""
    expert: Transitions
    """The expert transitions (``expert_transitions``), environment observations."""
    expert_agent_obs: jax.Array
    """(M,) + agent obs shape: ``expert.obs`` as the agent sees them (the time feature of each
    demo step appended where the run appends one), for agents that act on expert states."""
    time_feature: bool
    """Whether the agent's observations end with the time feature (dropped before the reward
    sees them)."""
    rollouts: RolloutPlan | None = None
    """For a reward that learns from the policy's episodes (``update_from_rollouts``)."""
    expert_trajectories: jax.Array | None = None
    """(E, T, obs_dim) the demos' states s_1..s_T, T the episode horizon (with ``rollouts``)."""


def with_learned_reward(agent: TD3 | SAC, setup: LearnedRewardSetup) -> LearnedRewardAgent:
    """``agent`` (TD3 or SAC: any agent with ``update_step``, ``run_updates`` and
    ``metrics_of``) trained on ``setup.reward``, learned from the expert transitions and the
    replay buffer's; its updates run as ``agent.update`` would, on batches rewarded by the
    reward."""
    reward, time_feature = setup.reward, setup.time_feature
    update_step = functools.partial(_update_step, agent, reward, time_feature)
    agent_updates = functools.partial(_agent_updates, agent, update_step)
    # Called only where a schedule is set, which only rewards that learn by update have.
    batch_learned = cast(LearnedReward, reward)
    reward_steps_jit = jax.jit(
        functools.partial(reward_steps, batch_learned, time_feature), static_argnames="num_steps"
    )
    return LearnedRewardAgent(
        obs_dim=agent.obs_dim,
        action_dim=agent.action_dim,
        max_action=agent.max_action,
        init=functools.partial(_init, agent, reward, setup.expert),
        act=agent.act,
        update=functools.partial(
            _update,
            setup,
            jax.jit(agent_updates, static_argnames="num_updates"),
            reward_steps_jit,
        ),
        set_normalizer=functools.partial(_set_normalizer, agent),
        q_values=lambda state, obs, action: agent.q_values(state.agent, obs, action),
        rewards=jax.jit(lambda state, obs, next_obs: reward.reward(state.reward, obs, next_obs)),
        rollouts=setup.rollouts,
        learn_from_rollouts=None if setup.rollouts is None else _rollout_learning(setup),
    )


def _init(
    agent: TD3 | SAC, reward: LearnedReward | RolloutLearnedReward, expert: Transitions, seed: int
) -> LearnedRewardState:
    key, k_reward = jax.random.split(jax.random.fold_in(jax.random.PRNGKey(seed), 1))
    return LearnedRewardState(
        agent=agent.init(seed),
        reward=reward.init(k_reward, expert),
        updates=jnp.array(0, jnp.int32),
        key=key,
    )


def _update_step(
    agent: TD3 | SAC,
    reward: LearnedReward | RolloutLearnedReward,
    time_feature: bool,
    state: LearnedRewardState,
    batch: ReplayData,
    key: jax.Array,
    **kwargs: Any,
) -> tuple[LearnedRewardState, tuple[jax.Array, ...]]:
    """The agent's update step on ``batch`` rewarded by the reward's current parameters."""
    rewards = reward.reward(
        state.reward,
        env_observations(batch.obs, time_feature),
        env_observations(batch.next_obs, time_feature),
    )
    agent_state, out = agent.update_step(state.agent, batch._replace(reward=rewards), key, **kwargs)
    state = state.replace(agent=agent_state, updates=state.updates + 1)
    return state, (*out, jnp.mean(rewards))


def _agent_updates(
    agent: TD3 | SAC,
    update_step: Callable[..., Any],
    state: LearnedRewardState,
    data: ReplayData,
    size: jax.Array | int,
    num_updates: int,
) -> tuple[LearnedRewardState, dict[str, jax.Array]]:
    state, outs = agent.run_updates(update_step, state, data, size, num_updates, state.agent.step)
    return state, {**agent.metrics_of(outs, state.agent), "reward_mean": jnp.mean(outs[-1])}


def _update(
    setup: LearnedRewardSetup,
    agent_updates: Callable[..., tuple[LearnedRewardState, dict[str, jax.Array]]],
    reward_steps: Callable[..., tuple[LearnedRewardState, dict[str, jax.Array]]],
    state: LearnedRewardState,
    data: ReplayData,
    size: jax.Array | int,
    num_updates: int,
) -> tuple[LearnedRewardState, dict[str, jax.Array]]:
    """The reward's steps that fall due in these updates, then the agent's updates."""
    metrics: dict[str, jax.Array] = {}
    due = 0 if setup.schedule is None else setup.schedule.steps_due(int(state.updates), num_updates)
    if due:
        state, metrics = reward_steps(state, data, size, setup.expert, num_steps=due)
    state, agent_metrics = agent_updates(state, data, size, num_updates=num_updates)
    return state, {**agent_metrics, **metrics}


def _set_normalizer(
    agent: TD3 | SAC, state: LearnedRewardState, mean: ArrayLike, std: ArrayLike
) -> LearnedRewardState:
    return state.replace(agent=agent.set_normalizer(state.agent, mean, std))


def _rollout_learning(
    setup: LearnedRewardSetup,
) -> Callable[..., tuple[LearnedRewardState, dict[str, jax.Array]]]:
    """``learn_from_rollouts`` of a reward that learns from the policy's episodes."""
    # Built only where setup.rollouts is set, which only such rewards (f-IRL's) have.
    reward = cast(RolloutLearnedReward, setup.reward)

    def learn(state: LearnedRewardState, trajectories: jax.Array, expert_trajs: jax.Array):
        key, k_reward = jax.random.split(state.key)
        reward_state, metrics = reward.update_from_rollouts(
            state.reward, trajectories, expert_trajs, k_reward
        )
        return state.replace(reward=reward_state, key=key), metrics

    learn_jit = jax.jit(learn)

    def learn_from_rollouts(state: LearnedRewardState, trajectories: Any):
        trajectories = jnp.asarray(trajectories, jnp.float32)
        return learn_jit(state, trajectories, setup.expert_trajectories)

    return learn_from_rollouts
