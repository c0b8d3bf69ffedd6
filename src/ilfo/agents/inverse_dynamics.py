"""An inverse dynamics model a = f(s, s'), trained on the learner's own transitions (OPOLO).

As in the OPOLO authors' code (opolo-code ``gail/idm.py``): an MLP (2x256 tanh, Glorot, linear
output) on (s, s') standardised by running statistics of the replay batches it trains on; the
loss is the mean squared error to the replay actions plus ``l2`` times half the sum of squares
of all its parameters (TensorFlow's ``l2_loss``), minimised by Adam.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import flax
import jax
import jax.numpy as jnp
import optax

from ilfo.networks import MLP, Activation, InitName
from ilfo.ranges import check_fields, learning_rate, non_negative, widths

__all__ = [
    "InverseDynamics",
    "InverseDynamicsConfig",
    "InverseDynamicsState",
    "RunningMoments",
    "update_moments",
]


class RunningMoments(flax.struct.PyTreeNode):
    """Running mean and variance of vectors (a pytree), as the authors' RunningMeanStd: it
    starts from a pseudo-count of 1e-2 with mean 0 and variance 1, and its std is floored at
    0.1 (sqrt(max(var, 1e-2)))."""

    count: jax.Array
    mean: jax.Array
    var: jax.Array

    @classmethod
    def create(cls, dim: int) -> RunningMoments:
        return cls(jnp.array(1e-2, jnp.float32), jnp.zeros(dim), jnp.ones(dim))

    @property
    def std(self) -> jax.Array:
        return jnp.sqrt(jnp.maximum(self.var, 1e-2))


def update_moments(moments: RunningMoments, x: jax.Array) -> RunningMoments:
    """The moments with the rows of ``x`` (B, dim) added (Chan et al.'s parallel update)."""
    n = jnp.asarray(x.shape[0], jnp.float32)
    mean, var = jnp.mean(x, axis=0), jnp.var(x, axis=0)
    total = moments.count + n
    delta = mean - moments.mean
    new_mean = moments.mean + delta * n / total
    m2 = moments.var * moments.count + var * n + delta**2 * moments.count * n / total
    return RunningMoments(total, new_mean, m2 / total)


@dataclasses.dataclass(frozen=True)
class InverseDynamicsConfig:
    """The inverse dynamics model. Defaults: the OPOLO authors' code."""

    hidden: tuple[int, ...] = widths((256, 256))
    """Hidden layer widths."""
    activation: Activation = "tanh"
    """Hidden activation."""
    init_scheme: InitName = "glorot"
    """Initialisation (see ``ilfo.networks``)."""
    lr: float = learning_rate(3e-4)
    """Adam learning rate."""
    l2: float = non_negative(1e-3)
    """Weight of half the sum of squared parameters in the loss."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


class InverseDynamicsState(flax.struct.PyTreeNode):
    params: Any
    opt_state: optax.OptState
    moments: RunningMoments
    """Running statistics of the (s, s') inputs it trained on."""


class InverseDynamics:
    """f(s, s') -> a, pure functions (the config closed over)."""

    def __init__(self, config: InverseDynamicsConfig, obs_dim: int, action_dim: int) -> None:
        self.config = config
        self.obs_dim = obs_dim
        self._net = MLP(config.hidden, action_dim, config.init_scheme, config.activation)
        self._opt = optax.adam(config.lr)

    def init(self, key: jax.Array) -> InverseDynamicsState:
        params = self._net.init(key, jnp.zeros((1, 2 * self.obs_dim), jnp.float32))
        moments = RunningMoments.create(2 * self.obs_dim)
        return InverseDynamicsState(params, self._opt.init(params), moments)

    def predict(self, state: InverseDynamicsState, obs: jax.Array, next_obs: jax.Array):
        """Predicted actions (B, action_dim) of transitions (B, obs_dim) each."""
        x = jnp.concatenate([obs, next_obs], axis=-1)
        return self._net.apply(state.params, (x - state.moments.mean) / state.moments.std)

    def update(
        self, state: InverseDynamicsState, obs: jax.Array, action: jax.Array, next_obs: jax.Array
    ) -> tuple[InverseDynamicsState, jax.Array]:
        """One Adam step on a batch of learner transitions; the input statistics first take
        the batch in. Returns the new state and the batch's mean squared error."""
        moments = update_moments(state.moments, jnp.concatenate([obs, next_obs], axis=-1))
        state = state.replace(moments=moments)

        def loss_fn(params: Any) -> tuple[jax.Array, jax.Array]:
            mse = jnp.mean(
                (self.predict(state.replace(params=params), obs, next_obs) - action) ** 2
            )
            l2 = sum(jnp.sum(p**2) for p in jax.tree.leaves(params)) / 2
            return mse + self.config.l2 * l2, mse

        (_, mse), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.params)
        updates, opt_state = self._opt.update(grads, state.opt_state, state.params)
        return state.replace(
            params=optax.apply_updates(state.params, updates), opt_state=opt_state
        ), mse
