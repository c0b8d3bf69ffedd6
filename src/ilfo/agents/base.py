"""The ``AgentFunctions`` protocol: what the training loop, evaluation and experts need of an agent.

TD3 (DDPG as its config) and SAC provide it as NamedTuples of pure functions built by their
factories (``make_td3``, ``make_sac``), closing over a frozen config; the state is an explicit
pytree. Agents know nothing of rewards: ``update`` reads rewards from the replay data.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

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
