"""The agent protocols: what the training loop, evaluation and experts need of an agent.

``AgentFunctions``: an off-policy agent, updated from a replay buffer after each episode.
``OnPolicyAgentFunctions``: an on-policy agent (TRPO), which learns from an ``OnPolicyBatch`` of
its own fresh episodes once it has collected enough of them.

TD3 (DDPG as its config) and SAC provide it as NamedTuples of pure functions built by their
factories (``make_td3``, ``make_sac``), closing over a frozen config; the state is an explicit
pytree. Agents know nothing of rewards: ``update`` reads rewards from the replay data.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import jax
from numpy.typing import ArrayLike


class AgentFunctions(Protocol):
    """An off-policy agent's functions (``TD3`` and ``SAC`` are ones)."""

    obs_dim: int
    """Observation size, the time feature included where the run appends it."""
    action_dim: int
    max_action: float
    init: Callable[[int], Any]
    """init(seed) -> state with fresh parameters and an identity normaliser."""
    act: Callable[..., jax.Array]
    """act(state or Policy, obs (..., obs_dim), key=None) -> action (..., action_dim); key None:
    the deterministic action, else an exploratory one."""
    update: Callable[..., tuple[Any, dict[str, jax.Array]]]
    """update(state, data: ReplayData, size, num_updates) -> (state, metrics), ``num_updates``
    updates on batches drawn from slots [0, size) of ``data``."""
    set_normalizer: Callable[[Any, ArrayLike, ArrayLike], Any]
    """set_normalizer(state, mean, std) -> state; allowed once."""
    q_values: Callable[[Any, jax.Array, jax.Array], jax.Array]
    """q_values(state, obs, action) -> (num_critics, ...) online critic values."""


class OnPolicyBatch(NamedTuple):
    """The steps an on-policy agent learns from in one iteration, in collection order."""

    obs: ArrayLike
    """(N, obs_dim) agent observations, as ``act`` saw them (time feature included)."""
    action: ArrayLike
    """(N, action_dim) the actions taken, as the policy drew them (before any clipping to the
    environment's box)."""
    reward: ArrayLike
    """(N,) rewards."""
    episode_end: ArrayLike
    """(N,) bool: True on the last step of each episode (the batch's last step is one); returns
    are never bootstrapped across it."""


class OnPolicyAgentFunctions(Protocol):
    """An on-policy agent's functions (TRPO): it learns from whole batches of fresh episodes of
    its own policy, then forgets them, instead of from a replay buffer."""

    obs_dim: int
    action_dim: int
    max_action: float
    batch_steps: int
    """The loop calls ``learn`` once it has collected at least this many steps (whole
    episodes) since the last call."""
    init: Callable[[int], Any]
    act: Callable[..., jax.Array]
    """act(state or Policy, obs, key=None) -> action; key None: deterministic. Actions may lie
    outside [-max_action, max_action]: the loop clips what it sends to the environment."""
    set_normalizer: Callable[[Any, ArrayLike, ArrayLike], Any]
    learn: Callable[[Any, OnPolicyBatch], tuple[Any, dict[str, float]]]
    """learn(state, batch) -> (state, metrics): one iteration on the batch."""
