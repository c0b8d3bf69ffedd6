"""Helpers shared by the agents (not public API)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax
from numpy.typing import ArrayLike

from ilfo.replay import ReplayData, sample_batch


class Policy(flax.struct.PyTreeNode):
    """What acting needs of an agent state (a pytree): the actor and the observation normaliser.

    The agents' ``act`` takes a full state or a ``Policy``. A ``Policy`` has a handful of leaves
    where a state has dozens (critics, targets, optimiser moments), and a jitted call flattens
    every leaf of its arguments, so acting step by step from a ``Policy`` dispatches faster. It
    is also what policy files hold (``flax.serialization``: keys actor_params, obs_mean,
    obs_std).
    """

    actor_params: Any
    obs_mean: jax.Array
    """(obs_dim,) the networks see (obs - obs_mean) / obs_std."""
    obs_std: jax.Array
    """(obs_dim,)"""


def policy_of(state: Any) -> Policy:
    """The ``Policy`` of an agent state (no copy: the same arrays)."""
    return Policy(state.actor_params, state.obs_mean, state.obs_std)


def as_float_bound(max_action: float | ArrayLike) -> float:
    bound = np.asarray(max_action, dtype=np.float64)
    if bound.size == 0 or not np.all(bound == bound.flat[0]) or bound.flat[0] <= 0:
        raise ValueError("max_action must be one positive bound shared by all action dimensions")
    return float(bound.flat[0])


def make_optimizer(lr: float, grad_clip: float | None) -> optax.GradientTransformation:
    if grad_clip is None:
        return optax.adam(lr)
    return optax.chain(optax.clip_by_global_norm(grad_clip), optax.adam(lr))


def make_normalizer_setter(
    obs_dim: int, time_feature: bool
) -> Callable[[Any, ArrayLike, ArrayLike], Any]:
    """Build ``set_normalizer(state, mean, std) -> state`` for states with obs_mean/obs_std.

    mean, std: (obs_dim,), or (obs_dim - 1,) when the observation ends with a time feature
    (the time feature then gets mean 0, std 1). Raises if the normaliser was already set.
    """

    def set_normalizer(state: Any, mean: ArrayLike, std: ArrayLike) -> Any:
        if bool(state.normalizer_set):
            raise RuntimeError("the observation normaliser can be set only once")
        mean = np.asarray(mean, np.float32)
        std = np.asarray(std, np.float32)
        if time_feature and mean.shape == (obs_dim - 1,):
            mean = np.append(mean, np.float32(0.0))
        if time_feature and std.shape == (obs_dim - 1,):
            std = np.append(std, np.float32(1.0))
        if mean.shape != (obs_dim,) or std.shape != (obs_dim,):
            raise ValueError(f"mean and std must have shape ({obs_dim},)")
        if not np.all(np.isfinite(mean)) or not np.all(std > 0):
            raise ValueError("mean must be finite and std positive")
        return state.replace(
            obs_mean=jnp.asarray(mean), obs_std=jnp.asarray(std), normalizer_set=jnp.array(True)
        )

    return set_normalizer


def scan_updates(
    update_step: Callable[[Any, ReplayData, jax.Array], tuple[Any, Any]],
    state: Any,
    data: ReplayData,
    size: jax.Array | int,
    num_updates: int,
    batch_size: int,
) -> tuple[Any, Any]:
    """``num_updates`` applications of ``update_step`` in one ``lax.scan``, each on a uniform
    batch from slots [0, size) of ``data``; keys come from ``state.key``. Returns the final
    state and the per-update outputs stacked on a leading axis."""
    return scan_update_groups((update_step,), state, data, size, num_updates, batch_size)


def scan_update_groups(
    update_steps: Sequence[Callable[[Any, ReplayData, jax.Array], tuple[Any, Any]]],
    state: Any,
    data: ReplayData,
    size: jax.Array | int,
    num_groups: int,
    batch_size: int,
) -> tuple[Any, Any]:
    """``num_groups`` times, apply each of ``update_steps`` in turn, in one ``lax.scan``; each
    update is drawn and keyed exactly as ``scan_updates`` draws it. Returns the final state and
    the per-update outputs stacked on a leading axis of ``num_groups * len(update_steps)``.

    A group whose steps differ statically (TD3's delayed actor: critic-only updates, then one
    with the actor) needs no run-time ``cond``, which XLA schedules poorly on a CPU."""

    def body(state: Any, _: None) -> tuple[Any, Any]:
        outs = []
        for update_step in update_steps:
            key, k_batch, k_step = jax.random.split(state.key, 3)
            state = state.replace(key=key)
            state, out = update_step(state, sample_batch(data, size, k_batch, batch_size), k_step)
            outs.append(out)
        return state, jax.tree.map(lambda *xs: jnp.stack(xs), *outs)

    state, outs = jax.lax.scan(body, state, None, length=num_groups)
    return state, jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), outs)
