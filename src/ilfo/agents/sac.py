"""Soft Actor-Critic (Haarnoja et al. 2018, "SAC: Algorithms and Applications", v2).

Twin critics with target networks (no separate value network), a tanh-squashed Gaussian actor and
an automatically tuned temperature whose target entropy defaults to -action_dim.

Usage mirrors TD3::

    agent = make_sac(SACConfig(), obs_dim, action_dim, max_action)
    state = agent.init(seed=0)
    action = agent.act(state, obs, key)            # sample; key=None: max_action * tanh(mean)
    state, metrics = agent.update(state, buffer.data, buffer.size, num_updates=1000)
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import flax
import jax
import jax.numpy as jnp
import optax
from numpy.typing import ArrayLike

from ilfo.agents._common import (
    Policy,
    as_float_bound,
    make_normalizer_setter,
    make_optimizer,
    scan_updates,
)
from ilfo.networks import (
    CriticEnsemble,
    SquashedGaussianActor,
    deterministic_squashed,
    sample_squashed,
)
from ilfo.ranges import batch, check_fields, count, fraction, learning_rate, positive, widths
from ilfo.replay import ReplayData

__all__ = ["SAC", "SACConfig", "SACState", "make_sac"]

Params = Any


@dataclasses.dataclass(frozen=True)
class SACConfig:
    """Hyperparameters of SAC; defaults from Haarnoja et al. 2018 (v2), Table 1."""

    actor_hidden: tuple[int, ...] = widths((256, 256))
    """Hidden layer widths of the actor MLP (ReLU)."""
    critic_hidden: tuple[int, ...] = widths((256, 256))
    """Hidden layer widths of each critic MLP (ReLU)."""
    num_critics: int = count(2)
    """Number of critics; targets and the actor loss use their minimum."""
    batch_size: int = batch(256)
    """Transitions per gradient step."""
    gamma: float = fraction(0.99)
    """Discount factor."""
    tau: float = fraction(0.005)
    """Polyak rate of the target critics, updated after every update."""
    lr_actor: float = learning_rate(3e-4, zero=True)
    """Adam learning rate of the actor."""
    lr_critic: float = learning_rate(3e-4, zero=True)
    """Adam learning rate of the critics."""
    lr_temperature: float = learning_rate(3e-4, zero=True)
    """Adam learning rate of log(temperature)."""
    init_temperature: float = positive(1.0)
    """Initial entropy temperature alpha."""
    autotune: bool = True
    """Learn the temperature so that the policy entropy tracks ``target_entropy``; False keeps
    ``init_temperature`` fixed."""
    target_entropy: float | None = None
    """Target entropy of the action distribution; None = -action_dim."""
    critic_grad_clip: float | None = positive(None)
    """Clip the critics' global gradient norm to this value; None = no clipping."""
    reward_scale: float = positive(1.0)
    """Rewards are multiplied by this in the critic's target (Haarnoja et al. 2018a, v1). It sets
    the reward's weight against the entropy bonus: tasks whose per-step rewards are tiny (e.g.
    Minitaur, ~0.01) learn little at 1."""
    log_std_min: float = -20.0
    """Lower clip of the actor's log std."""
    log_std_max: float = 2.0
    """Upper clip of the actor's log std."""
    critic_layer_norm: bool = False
    """A LayerNorm in each hidden layer of the critics, before the activation (Ball et al.
    2023; SimBa's normalised critics); off in Haarnoja et al.'s SAC."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)
        if not self.log_std_min < self.log_std_max:
            raise ValueError(
                f"log_std_min must be below log_std_max, got {self.log_std_min} and "
                f"{self.log_std_max}"
            )


class SACState(flax.struct.PyTreeNode):
    """Everything SAC learns or needs to continue learning (a pytree)."""

    actor_params: Params
    critic_params: Params
    """Parameters of all critics, stacked on a leading axis of size num_critics."""
    critic_target: Params
    log_temperature: jax.Array
    """() log of the entropy temperature alpha."""
    actor_opt_state: optax.OptState
    critic_opt_state: optax.OptState
    temperature_opt_state: optax.OptState
    obs_mean: jax.Array
    """(obs_dim,) networks see (obs - obs_mean) / obs_std."""
    obs_std: jax.Array
    """(obs_dim,)"""
    normalizer_set: jax.Array
    """() bool, True once ``set_normalizer`` has been called."""
    step: jax.Array
    """() int32, updates done so far."""
    key: jax.Array
    """PRNG key consumed by ``update``."""


class SAC(NamedTuple):
    """The functions of a SAC agent built by ``make_sac`` (config closed over)."""

    config: SACConfig
    obs_dim: int
    action_dim: int
    max_action: float
    init: Callable[[int], SACState]
    """init(seed) -> state with fresh parameters and an identity normaliser."""
    act: Callable[..., jax.Array]
    """act(state or Policy, obs (..., obs_dim), key=None) -> action (..., action_dim). key None:
    max_action * tanh(mean); else a sample of the policy."""
    update: Callable[..., tuple[SACState, dict[str, jax.Array]]]
    """update(state, data: ReplayData, size, num_updates) -> (state, metrics)."""
    set_normalizer: Callable[[SACState, ArrayLike, ArrayLike], SACState]
    """set_normalizer(state, mean (obs_dim,), std (obs_dim,)) -> state; allowed once."""
    q_values: Callable[[SACState, jax.Array, jax.Array], jax.Array]
    """q_values(state, obs (..., obs_dim), action (..., action_dim)) -> (num_critics, ...): the
    online critics' values, observations normalised as in training (for diagnostics)."""
    update_step: Callable[..., tuple[SACState, tuple[jax.Array, ...]]]
    """update_step(state, batch, key) -> (state, outputs): one update on one batch, not jitted,
    for updates that wrap it (a learned reward relabels ``batch.reward`` first)."""
    run_updates: Callable[..., tuple[Any, tuple[jax.Array, ...]]]
    """run_updates(step, state, data, size, num_updates, updates_done) -> (state, outputs):
    ``num_updates`` applications of ``step`` (``update_step`` or a wrapper of it, on any state
    with a ``key``) in one ``lax.scan``, as ``update`` runs them."""
    metrics_of: Callable[[tuple[jax.Array, ...], SACState], dict[str, jax.Array]]
    """metrics_of(stacked outputs, final state) -> the scalar metrics ``update`` reports."""


def sac_metrics(outs: tuple[jax.Array, ...], state: SACState) -> dict[str, jax.Array]:
    """Scalar metrics of stacked ``update_step`` outputs and the final state."""
    c_loss, a_loss, q_mean, entropy = outs[:4]
    return {
        "critic_loss": jnp.mean(c_loss),
        "actor_loss": jnp.mean(a_loss),
        "q_mean": jnp.mean(q_mean),
        "entropy": jnp.mean(entropy),
        "temperature": jnp.exp(state.log_temperature),
    }


class _Networks(NamedTuple):
    """SAC's modules, optimisers and constants, built once from the config (static)."""

    actor: SquashedGaussianActor
    critic: CriticEnsemble
    actor_opt: optax.GradientTransformation
    critic_opt: optax.GradientTransformation
    temperature_opt: optax.GradientTransformation
    max_action: float
    target_entropy: float


def _normalize(state: SACState | Policy, obs: jax.Array) -> jax.Array:
    return (obs - state.obs_mean) / state.obs_std


def _policy(
    nets: _Networks, params: Params, obs_n: jax.Array, key: jax.Array
) -> tuple[jax.Array, jax.Array]:
    mean, log_std = nets.actor.apply(params, obs_n)
    return sample_squashed(key, mean, log_std, nets.max_action)


def _init_state(
    nets: _Networks, cfg: SACConfig, obs_dim: int, action_dim: int, seed: int
) -> SACState:
    key, k_actor, k_critic = jax.random.split(jax.random.PRNGKey(seed), 3)
    obs = jnp.zeros((1, obs_dim), jnp.float32)
    action = jnp.zeros((1, action_dim), jnp.float32)
    actor_params = nets.actor.init(k_actor, obs)
    critic_params = nets.critic.init(k_critic, obs, action)
    log_temperature = jnp.log(jnp.asarray(cfg.init_temperature, jnp.float32))
    return SACState(
        actor_params=actor_params,
        critic_params=critic_params,
        critic_target=critic_params,
        log_temperature=log_temperature,
        actor_opt_state=nets.actor_opt.init(actor_params),
        critic_opt_state=nets.critic_opt.init(critic_params),
        temperature_opt_state=nets.temperature_opt.init(log_temperature),
        obs_mean=jnp.zeros(obs_dim, jnp.float32),
        obs_std=jnp.ones(obs_dim, jnp.float32),
        normalizer_set=jnp.array(False),
        step=jnp.array(0, jnp.int32),
        key=key,
    )


def _update_step(
    nets: _Networks, cfg: SACConfig, state: SACState, batch: ReplayData, key: jax.Array
):
    """One SAC update (critics, actor, temperature, targets) on one batch."""
    k_next, k_pi = jax.random.split(key)
    obs_n = _normalize(state, batch.obs)
    next_obs_n = _normalize(state, batch.next_obs)
    temperature = jnp.exp(state.log_temperature)

    # Critic: soft TD target with the current policy at s'.
    next_action, next_logp = _policy(nets, state.actor_params, next_obs_n, k_next)
    next_q = jnp.min(nets.critic.apply(state.critic_target, next_obs_n, next_action), axis=0)
    target = cfg.reward_scale * batch.reward + cfg.gamma * batch.not_done * (
        next_q - temperature * next_logp
    )
    target = jax.lax.stop_gradient(target)

    def critic_loss_fn(params: Params) -> tuple[jax.Array, jax.Array]:
        q = nets.critic.apply(params, obs_n, batch.action)  # (num_critics, B)
        return jnp.sum(jnp.mean((q - target) ** 2, axis=-1)), jnp.mean(q)

    (c_loss, q_mean), grads = jax.value_and_grad(critic_loss_fn, has_aux=True)(state.critic_params)
    updates, critic_opt_state = nets.critic_opt.update(
        grads, state.critic_opt_state, state.critic_params
    )
    critic_params = optax.apply_updates(state.critic_params, updates)

    # Actor: minimise alpha * log pi - min_i Q_i with the updated critics.
    def actor_loss_fn(params: Params) -> tuple[jax.Array, jax.Array]:
        action, logp = _policy(nets, params, obs_n, k_pi)
        q = jnp.min(nets.critic.apply(critic_params, obs_n, action), axis=0)
        return jnp.mean(temperature * logp - q), logp

    (a_loss, logp), a_grads = jax.value_and_grad(actor_loss_fn, has_aux=True)(state.actor_params)
    a_updates, actor_opt_state = nets.actor_opt.update(
        a_grads, state.actor_opt_state, state.actor_params
    )
    actor_params = optax.apply_updates(state.actor_params, a_updates)

    # Temperature: J(log alpha) = E[-log alpha * (log pi + nets.target_entropy)].
    entropy = -jnp.mean(logp)
    log_temperature = state.log_temperature
    temperature_opt_state = state.temperature_opt_state
    if cfg.autotune:
        gap = jax.lax.stop_gradient(jnp.mean(logp) + nets.target_entropy)
        t_grad = -gap  # d/d(log alpha) of -log alpha * gap
        t_updates, temperature_opt_state = nets.temperature_opt.update(
            t_grad, state.temperature_opt_state, log_temperature
        )
        log_temperature = optax.apply_updates(log_temperature, t_updates)

    critic_target = optax.incremental_update(critic_params, state.critic_target, cfg.tau)
    new_state = state.replace(
        actor_params=actor_params,
        critic_params=critic_params,
        critic_target=critic_target,
        log_temperature=log_temperature,
        actor_opt_state=actor_opt_state,
        critic_opt_state=critic_opt_state,
        temperature_opt_state=temperature_opt_state,
        step=state.step + 1,
    )
    return new_state, (c_loss, a_loss, q_mean, entropy)


def make_sac(
    config: SACConfig, obs_dim: int, action_dim: int, max_action: float | ArrayLike = 1.0
) -> SAC:
    """Build the pure functions of a SAC agent.

    Args:
        config: hyperparameters.
        obs_dim: observation size.
        action_dim: action size.
        max_action: bound of the symmetric action box [-max_action, max_action], the same for
            every dimension.
    """
    cfg = config
    max_action = as_float_bound(max_action)
    nets = _Networks(
        actor=SquashedGaussianActor(cfg.actor_hidden, action_dim, cfg.log_std_min, cfg.log_std_max),
        critic=CriticEnsemble(cfg.critic_hidden, cfg.num_critics, layer_norm=cfg.critic_layer_norm),
        actor_opt=optax.adam(cfg.lr_actor),
        critic_opt=make_optimizer(cfg.lr_critic, cfg.critic_grad_clip),
        temperature_opt=optax.adam(cfg.lr_temperature),
        max_action=max_action,
        target_entropy=-float(action_dim) if cfg.target_entropy is None else cfg.target_entropy,
    )
    update_step = functools.partial(_update_step, nets, cfg)

    @jax.jit
    def act(state: SACState | Policy, obs: jax.Array, key: jax.Array | None = None) -> jax.Array:
        mean, log_std = nets.actor.apply(state.actor_params, _normalize(state, obs))
        if key is None:
            return deterministic_squashed(mean, max_action)
        return sample_squashed(key, mean, log_std, max_action)[0]

    @jax.jit
    def q_values(state: SACState, obs: jax.Array, action: jax.Array) -> jax.Array:
        return nets.critic.apply(state.critic_params, _normalize(state, obs), action)

    def update(
        state: SACState, data: ReplayData, size: jax.Array | int, num_updates: int
    ) -> tuple[SACState, dict[str, jax.Array]]:
        """Run ``num_updates`` SAC updates in one jitted ``lax.scan``.

        Each update draws a uniform batch of ``config.batch_size`` transitions from slots
        ``[0, size)`` of ``data`` (a ``ReplayData``; arrays (N, ...)). ``size`` may change
        between calls without recompiling; ``num_updates`` is static. Returns the new state and
        scalar metrics: mean critic loss, actor loss, Q, policy entropy, and the final
        temperature."""

        state, outs = scan_updates(update_step, state, data, size, num_updates, cfg.batch_size)
        return state, sac_metrics(outs, state)

    def run_updates(step, state, data, size, num_updates: int, updates_done):
        return scan_updates(step, state, data, size, num_updates, cfg.batch_size)

    return SAC(
        config=cfg,
        obs_dim=obs_dim,
        action_dim=action_dim,
        max_action=max_action,
        init=functools.partial(_init_state, nets, cfg, obs_dim, action_dim),
        act=act,
        update=jax.jit(update, static_argnames="num_updates"),
        set_normalizer=make_normalizer_setter(obs_dim, time_feature=False),
        q_values=q_values,
        update_step=update_step,
        run_updates=run_updates,
        metrics_of=sac_metrics,
    )
