"""A state-transition discriminator D(s, s') and its reward: GAIfO / DACfO and OPOLO's reward.

As in the OPOLO authors' code (illidanlab/opolo-code, ``gail/gaifo.py``; docs/reproduction.md):
D is an MLP (2x256 tanh, Glorot initialisation) on (s, s') normalised by the expert states'
statistics, giving the logit of P(expert | s, s'). It minimises the binary cross-entropy with
expert transitions labelled 1 and the learner's (uniform draws from the replay buffer) 0, minus
0.001 times the mean Bernoulli entropy of its outputs, plus 10 times the WGAN-GP gradient
penalty mean((|grad_x logit(x_hat)| - 1)^2) at interpolates x_hat between expert and learner
inputs. The reward is -log(1 - D(s, s')), 1 - D clipped to [1e-4, 1 - 1e-8]: positive, larger
where the learner's transitions look like the expert's.

Where ilfo departs (both documented in docs/reproduction.md): the interpolation weight is drawn
per sample at every step (the authors' code draws one weight per input feature once, when its
graph is built, and keeps it for the whole run), and the input statistics are the expert
states' exact mean and std (the authors' are running estimates from the expert batches, which
converge to the same values; both floor the std at 0.1).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import flax
import jax
import jax.numpy as jnp
import optax

from ilfo.networks import MLP, Activation, InitName
from ilfo.ranges import batch, check_fields, count, learning_rate, non_negative, positive, widths
from ilfo.rewards.learned import Transitions

__all__ = ["Discriminator", "DiscriminatorConfig", "DiscriminatorState", "gradient_penalty"]


@dataclasses.dataclass(frozen=True)
class DiscriminatorConfig:
    """The (s, s') discriminator and its training schedule. Defaults: the OPOLO authors' code
    (MuJoCo settings of opolo.yml and td3dacfo.yml)."""

    hidden: tuple[int, ...] = widths((256, 256))
    """Hidden layer widths."""
    activation: Activation = "tanh"
    """Hidden activation: "tanh" (the authors') or "relu"."""
    init_scheme: InitName = "glorot"
    """Initialisation: "glorot" (TensorFlow's default, the authors'), "torch" or "flax"."""
    lr: float = learning_rate(3e-4)
    """Adam learning rate (the authors use the agent's: 3e-4; 1e-3 for DACfO on Walker2d)."""
    entropy_coef: float = non_negative(1e-3)
    """Weight of the entropy bonus (subtracted from the loss)."""
    grad_penalty: float = non_negative(10.0)
    """Weight of the gradient penalty; 0 turns it off."""
    batch_size: int = batch(100)
    """Expert transitions and learner transitions per step (each)."""
    update_every: int = count(500)
    """Steps of the discriminator are taken every this many agent updates (with one update per
    environment step, the authors' every 500 environment steps)."""
    updates: int = count(10)
    """Gradient steps taken each time (the authors' 10)."""
    std_floor: float = positive(0.1)
    """Floor of the input standardisation's std (the authors' sqrt(1e-2))."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


class DiscriminatorState(flax.struct.PyTreeNode):
    """The discriminator's parameters, optimiser state and input statistics (a pytree)."""

    params: Any
    opt_state: optax.OptState
    obs_mean: jax.Array
    """(obs_dim,) expert states' mean; inputs are (s - mean) / std, s and s' alike."""
    obs_std: jax.Array
    """(obs_dim,) expert states' std, floored at ``std_floor``."""


def _bernoulli_entropy(logits: jax.Array) -> jax.Array:
    p = jax.nn.sigmoid(logits)
    return p * jax.nn.softplus(-logits) + (1.0 - p) * jax.nn.softplus(logits)


def gradient_penalty(
    logit_fn: Any, expert_x: jax.Array, learner_x: jax.Array, mix: jax.Array
) -> jax.Array:
    """WGAN-GP's penalty mean_b (|grad_x logit_fn(x_hat_b)| - 1)^2 at x_hat = mix * expert_x +
    (1 - mix) * learner_x; expert_x, learner_x (B, n), mix (B, 1) (or (1, n))."""
    x_hat = mix * expert_x + (1.0 - mix) * learner_x
    grads = jax.vmap(jax.grad(lambda x: logit_fn(x[None])[0]))(x_hat)
    return jnp.mean((jnp.linalg.norm(grads, axis=-1) - 1.0) ** 2)


class Discriminator:
    """D(s, s') as a ``LearnedReward`` (pure functions; the config closed over)."""

    def __init__(self, config: DiscriminatorConfig) -> None:
        self.config = config
        self.batch_size = config.batch_size
        self._net = MLP(config.hidden, 1, config.init_scheme, config.activation)
        self._opt = optax.adam(config.lr)

    def init(self, key: jax.Array, expert: Transitions) -> DiscriminatorState:
        """Fresh parameters, and input statistics from the expert states."""
        obs_dim = expert.obs.shape[-1]
        params = self._net.init(key, jnp.zeros((1, 2 * obs_dim), jnp.float32))
        std = jnp.maximum(jnp.std(expert.obs, axis=0), self.config.std_floor)
        return DiscriminatorState(params, self._opt.init(params), jnp.mean(expert.obs, 0), std)

    def _inputs(self, state: DiscriminatorState, obs: jax.Array, next_obs: jax.Array):
        norm = lambda x: (x - state.obs_mean) / state.obs_std  # noqa: E731
        return jnp.concatenate([norm(obs), norm(next_obs)], axis=-1)

    def logits(self, state: DiscriminatorState, obs: jax.Array, next_obs: jax.Array):
        """Logits (B,) of P(expert | s, s')."""
        return self._net.apply(state.params, self._inputs(state, obs, next_obs))[..., 0]

    def loss(
        self,
        params: Any,
        state: DiscriminatorState,
        learner: Transitions,
        expert: Transitions,
        key: jax.Array,
    ) -> tuple[jax.Array, dict[str, jax.Array]]:
        """The discriminator's loss at ``params`` and its parts (see the module docstring)."""
        cfg = self.config
        x_e = self._inputs(state, expert.obs, expert.next_obs)
        x_l = self._inputs(state, learner.obs, learner.next_obs)
        logit_fn = lambda x: self._net.apply(params, x)[..., 0]  # noqa: E731
        l_e, l_l = logit_fn(x_e), logit_fn(x_l)
        bce = jnp.mean(jax.nn.softplus(-l_e)) + jnp.mean(jax.nn.softplus(l_l))
        entropy = jnp.mean(_bernoulli_entropy(jnp.concatenate([l_e, l_l])))
        loss = bce - cfg.entropy_coef * entropy
        penalty = jnp.zeros(())
        if cfg.grad_penalty > 0:
            mix = jax.random.uniform(key, (x_e.shape[0], 1))
            penalty = gradient_penalty(logit_fn, x_e, x_l, mix)
            loss = loss + cfg.grad_penalty * penalty
        accuracy = 0.5 * (jnp.mean(l_e > 0) + jnp.mean(l_l < 0))
        return loss, {"reward_loss": bce, "reward_accuracy": accuracy, "grad_penalty": penalty}

    def update(
        self, state: DiscriminatorState, learner: Transitions, expert: Transitions, key: jax.Array
    ) -> tuple[DiscriminatorState, dict[str, jax.Array]]:
        """One Adam step on a batch of learner and of expert transitions."""
        grads, metrics = jax.grad(self.loss, has_aux=True)(
            state.params, state, learner, expert, key
        )
        updates, opt_state = self._opt.update(grads, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)
        return state.replace(params=params, opt_state=opt_state), metrics

    def reward(self, state: DiscriminatorState, obs: jax.Array, next_obs: jax.Array) -> jax.Array:
        """-log(1 - D(s, s')), 1 - D clipped to [1e-4, 1 - 1e-8]."""
        one_minus_d = jax.nn.sigmoid(-self.logits(state, obs, next_obs))
        return -jnp.log(jnp.clip(one_minus_d, 1e-4, 1.0 - 1e-8))
