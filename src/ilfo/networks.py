"""Neural networks shared by the agents (flax.linen).

All modules take batch-first inputs and accept any leading batch shape:

- ``DeterministicActor``: obs (..., obs_dim) -> action (..., action_dim), ``max_action * tanh``.
- ``CriticEnsemble``: (obs (..., obs_dim), action (..., action_dim)) -> Q (num_critics, ...).
  One ``Critic`` module vmapped over a leading ensemble axis of its parameters, so the twin
  critics of TD3/SAC run as one batched matmul chain instead of two.
- ``SquashedGaussianActor``: obs -> (mean, log_std) of the pre-tanh Gaussian, both
  (..., action_dim); use ``sample_squashed`` / ``deterministic_squashed`` to get actions.

Initialisation (``init_scheme``): ``"flax"`` (flax's default: LeCun-normal weights, zero biases) or
``"torch"`` (PyTorch's ``nn.Linear`` default, which the OOPS paper's code and Fujimoto's TD3 use:
weights and biases uniform in +-1/sqrt(fan_in)). They differ several-fold in scale: with
"torch" a fresh actor's actions and critic's values start near 0; with "flax" they start ~5-10x
larger.

Observation normalisation is not done here: the agents apply ``(obs - mean) / std`` before
calling the networks, so the networks stay plain functions of their inputs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal

import flax.linen as nn
import jax
import jax.numpy as jnp

__all__ = [
    "MLP",
    "ArrayModule",
    "Critic",
    "CriticEnsemble",
    "DeterministicActor",
    "PairModule",
    "SquashedGaussianActor",
    "deterministic_squashed",
    "ensemble",
    "sample_squashed",
]

_LOG_2 = math.log(2.0)

InitName = Literal["flax", "torch", "glorot"]
Activation = Literal["relu", "tanh"]
_ACTIVATIONS = {"relu": nn.relu, "tanh": nn.tanh}

if TYPE_CHECKING:
    # flax types Module.apply's result as Any | (output, mutated variables), the pair being for
    # apply(..., mutable=...), which ilfo never calls. These bases tell the type checker what
    # apply returns; at run time both are flax's Module itself.
    class ArrayModule(nn.Module):
        """A module whose ``apply`` returns one array."""

        def apply(self, variables: Any, *args: Any, **kwargs: Any) -> jax.Array: ...

    class PairModule(nn.Module):
        """A module whose ``apply`` returns two arrays (a Gaussian's mean and log std)."""

        def apply(
            self, variables: Any, *args: Any, **kwargs: Any
        ) -> tuple[jax.Array, jax.Array]: ...

else:
    ArrayModule = PairModule = nn.Module


def dense(features: int, fan_in: int, init_scheme: InitName) -> nn.Dense:
    """A dense layer initialised as ``init_scheme`` says (see the module docstring)."""
    if init_scheme == "flax":
        return nn.Dense(features)
    if init_scheme == "glorot":  # TensorFlow's default (the OPOLO authors' code)
        return nn.Dense(features, kernel_init=nn.initializers.xavier_uniform())
    if init_scheme != "torch":
        raise ValueError(f"init_scheme must be 'flax', 'torch' or 'glorot', got {init_scheme!r}")
    bound = 1.0 / fan_in**0.5

    def bias_init(key: jax.Array, shape: Sequence[int], dtype=jnp.float32) -> jax.Array:
        return jax.random.uniform(key, shape, dtype, -bound, bound)

    # variance_scaling(1/3, fan_in, uniform) draws from +-sqrt(3 * (1/3) / fan_in) = +-bound.
    kernel_init = nn.initializers.variance_scaling(1.0 / 3.0, "fan_in", "uniform")
    return nn.Dense(features, kernel_init=kernel_init, bias_init=bias_init)


class MLP(ArrayModule):
    """Multilayer perceptron (ReLU or tanh hidden layers) with a linear output layer.

    x (..., in_dim) -> (..., out_dim). ``layer_norm``: a LayerNorm after each hidden layer's
    matmul, before its activation (the critics of Ball et al. 2023 and SimBa's normalised
    hidden layers), which keeps a critic's features bounded as its targets grow.
    """

    hidden: Sequence[int]
    out_dim: int
    init_scheme: InitName = "flax"
    activation: Activation = "relu"
    layer_norm: bool = False

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        act = _ACTIVATIONS[self.activation]
        for width in self.hidden:
            x = dense(width, x.shape[-1], self.init_scheme)(x)
            x = act(nn.LayerNorm()(x) if self.layer_norm else x)
        return dense(self.out_dim, x.shape[-1], self.init_scheme)(x)


class DeterministicActor(ArrayModule):
    """TD3/DDPG actor: obs (..., obs_dim) -> max_action * tanh(MLP(obs)), (..., action_dim)."""

    hidden: Sequence[int]
    action_dim: int
    max_action: float | jax.Array = 1.0
    init_scheme: InitName = "flax"

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return self.max_action * jnp.tanh(MLP(self.hidden, self.action_dim, self.init_scheme)(obs))


class Critic(ArrayModule):
    """One Q-function: (obs (..., obs_dim), action (..., action_dim)) -> Q (...)."""

    hidden: Sequence[int]
    init_scheme: InitName = "flax"
    layer_norm: bool = False

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        x = jnp.concatenate([obs, action], axis=-1)
        return MLP(self.hidden, 1, self.init_scheme, layer_norm=self.layer_norm)(x)[..., 0]


def ensemble(member: type[nn.Module], size: int) -> type[nn.Module]:
    """``size`` independent copies of the module ``member`` run as one: their parameters on a
    leading axis (each copy initialised with its own key), every input shared, the outputs
    stacked on axis 0 (``nn.vmap``)."""
    return nn.vmap(
        member,
        variable_axes={"params": 0},
        split_rngs={"params": True},
        in_axes=None,
        out_axes=0,
        axis_size=size,
    )


class CriticEnsemble(ArrayModule):
    """``num_critics`` independent critics evaluated at once.

    (obs (..., obs_dim), action (..., action_dim)) -> Q (num_critics, ...).

    Parameters carry a leading axis of size ``num_critics`` (``nn.vmap`` with
    ``variable_axes={'params': 0}``, ``split_rngs={'params': True}``: each member gets its own
    initialisation). Slicing that axis of the parameter tree (``p[:1]``) and applying a
    ``CriticEnsemble(hidden, 1)`` evaluates a single member, which TD3's actor loss uses.
    """

    hidden: Sequence[int]
    num_critics: int = 2
    init_scheme: InitName = "flax"
    layer_norm: bool = False
    """A LayerNorm in each hidden layer of every critic (``MLP``)."""

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        members = ensemble(Critic, self.num_critics)
        critic = members(self.hidden, self.init_scheme, self.layer_norm, name="ensemble")
        return critic(obs, action)


class SquashedGaussianActor(PairModule):
    """SAC actor: obs (..., obs_dim) -> (mean, log_std), each (..., action_dim).

    The action is ``max_action * tanh(u)`` with ``u ~ N(mean, exp(log_std)^2)``; ``log_std`` is
    clipped to ``[log_std_min, log_std_max]`` (Haarnoja et al.'s -20 and 2).
    """

    hidden: Sequence[int]
    action_dim: int
    log_std_min: float = -20.0
    log_std_max: float = 2.0

    @nn.compact
    def __call__(self, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        out = MLP(self.hidden, 2 * self.action_dim)(obs)
        mean, log_std = jnp.split(out, 2, axis=-1)
        log_std = jnp.clip(log_std, self.log_std_min, self.log_std_max)
        return mean, log_std


def sample_squashed(
    key: jax.Array, mean: jax.Array, log_std: jax.Array, max_action: float | jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Reparameterised sample of ``max_action * tanh(u)``, ``u ~ N(mean, std^2)``.

    mean, log_std: (..., action_dim). Returns (action (..., action_dim), log_prob (...)), where
    log_prob is the log density of the returned action itself, tanh and ``max_action`` scaling
    included (change of variables), computed stably as
    ``log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u))``.
    """
    std = jnp.exp(log_std)
    eps = jax.random.normal(key, mean.shape, mean.dtype)
    u = mean + std * eps
    gauss_logp = -0.5 * eps**2 - log_std - 0.5 * jnp.log(2.0 * jnp.pi)
    log_det = 2.0 * (_LOG_2 - u - jax.nn.softplus(-2.0 * u)) + jnp.log(max_action)
    log_prob = jnp.sum(gauss_logp - log_det, axis=-1)
    return max_action * jnp.tanh(u), log_prob


def deterministic_squashed(mean: jax.Array, max_action: float | jax.Array) -> jax.Array:
    """The mode-like action ``max_action * tanh(mean)`` used for evaluation, (..., action_dim)."""
    return max_action * jnp.tanh(mean)
