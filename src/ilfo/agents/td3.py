"""TD3 (Fujimoto, van Hoof, Meger 2018) with the options the OOPS paper's code uses.

Options beyond plain TD3: the PAL critic loss (Fujimoto, Meger, Precup 2020), critic gradient
clipping, time augmentation of the critic's samples (``augment_time``), PyTorch's initialisation,
an observation normaliser fixed once, and DDPG as a configuration (``ddpg_config``).

Usage::

    agent = make_td3(TD3Config.paper(), obs_dim=12, action_dim=3, max_action=1.0)
    state = agent.init(seed=0)
    action = agent.act(state, obs, key)            # exploration; key=None: deterministic
    state, metrics = agent.update(state, buffer.data, buffer.size, num_updates=1000)

Everything in ``agent`` is a pure function of its arguments; ``act`` and ``update`` are jitted
(``num_updates`` is static: each distinct value compiles once). The config is closed over by
``make_td3``, never read from a global.
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
    scan_update_groups,
    scan_updates,
)
from ilfo.agents.critic_targets import (
    LossName,
    TimeAugmentationScheme,
    augment_time,
    critic_loss,
    redraw_next_time,
)
from ilfo.networks import CriticEnsemble, DeterministicActor, InitName
from ilfo.ranges import (
    batch,
    check_fields,
    count,
    fraction,
    learning_rate,
    non_negative,
    positive,
    widths,
)
from ilfo.replay import ReplayData

__all__ = [
    "TD3",
    "ActorTerm",
    "TD3Config",
    "TD3State",
    "ddpg_config",
    "delayed",
    "delayed_updates",
    "make_td3",
    "td3_metrics",
]

Params = Any


@dataclasses.dataclass(frozen=True)
class TD3Config:
    """Hyperparameters of TD3. The defaults are Fujimoto's reference TD3 (author's repository);
    use ``TD3Config.paper()`` for the OOPS paper's settings and ``TD3Config.fast()`` for CPU."""

    actor_hidden: tuple[int, ...] = widths((256, 256))
    """Hidden layer widths of the actor MLP (ReLU)."""
    critic_hidden: tuple[int, ...] = widths((256, 256))
    """Hidden layer widths of each critic MLP (ReLU)."""
    num_critics: int = count(2)
    """Number of critics; the TD target takes their minimum (clipped double Q). 1 = DDPG."""
    batch_size: int = batch(256)
    """Transitions per gradient step."""
    gamma: float = fraction(0.99)
    """Discount factor."""
    tau: float = fraction(0.005)
    """Polyak rate of the target networks: target <- tau * online + (1 - tau) * target."""
    lr_actor: float = learning_rate(3e-4, zero=True)
    """Adam learning rate of the actor."""
    lr_critic: float = learning_rate(3e-4, zero=True)
    """Adam learning rate of the critics."""
    exploration_noise: float = non_negative(0.1)
    """Std of the Gaussian noise added to actions when acting, in units of max_action."""
    target_noise: float = non_negative(0.2)
    """Std of the target policy smoothing noise, in units of max_action (0 = off)."""
    noise_clip: float = non_negative(0.5)
    """Target smoothing noise is clipped to +-noise_clip, in units of max_action."""
    policy_delay: int = count(2)
    """One actor and target update every policy_delay critic updates (1 = every update)."""
    critic_grad_clip: float | None = positive(None)
    """Clip the critics' global gradient norm to this value; None = no clipping."""
    loss: LossName = "mse"
    """Critic loss: "mse" (sum over critics of mean squared TD error, as in TD3), "huber"
    (delta 1), or "pal" (prioritised approximation loss, see ``pal_loss``)."""
    pal_alpha: float = non_negative(0.4)
    """PAL exponent alpha (priority = |td|^alpha)."""
    pal_min_priority: float = positive(1.0)
    """PAL minimum priority: quadratic region of the loss for |td| < pal_min_priority."""
    time_augmentation: bool = False
    """Observations end with a time feature remaining_steps / max_time. When True, the
    critic's samples get random times, as ``time_augmentation_scheme`` says; the actor loss
    uses the recorded time. In ``ilfo train`` the trainer decides whether observations carry
    the feature (fixed-horizon runs do), and this applies only where they do."""
    time_augmentation_scheme: TimeAugmentationScheme = "finite_horizon"
    """How time augmentation draws times: "finite_horizon" (current time k, next k - 1,
    bootstrapping cut at k = 1: a valid finite-horizon backup, ``augment_time``) or
    "next_only" (only the next observation's time redrawn from {1, ..., max_time}, the current
    time and the end-of-episode flag as recorded, ``redraw_next_time``: the paper's code as
    the design notes beside the repo, ../shared/design/reference-notes.md, describe it)."""
    init_scheme: InitName = "torch"
    """Network initialisation: "torch" (PyTorch's nn.Linear default, uniform +-1/sqrt(fan_in)
    for weights and biases, as the paper's and Fujimoto's code), "flax" (LeCun normal, zero
    biases) or "glorot" (Glorot uniform, zero biases: TensorFlow's, as the OPOLO code)."""
    max_time: int = count(1000)
    """Scale of the time feature and the largest time-to-go drawn by augmentation (the horizon);
    set by the trainer to the episode horizon in ``ilfo train``."""
    critic_layer_norm: bool = False
    """A LayerNorm in each hidden layer of the critics, before the activation (Ball et al.
    2023; SimBa's normalised critics); off in the paper's TD3."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)

    @classmethod
    def paper(cls, **overrides: Any) -> TD3Config:
        """The OOPS paper code's TD3: actor 256-256, twin critics 1024-1024, batch 100,
        tau 0.003, exploration noise 0.2, target noise 0.1 clipped at 0.5, policy delay 2,
        Adam 3e-4, critic gradient norm clipped at 25, PAL loss (alpha 0.4, min priority 1),
        time augmentation with horizon 1000."""
        base = cls(
            actor_hidden=(256, 256),
            critic_hidden=(1024, 1024),
            num_critics=2,
            batch_size=100,
            gamma=0.99,
            tau=0.003,
            lr_actor=3e-4,
            lr_critic=3e-4,
            exploration_noise=0.2,
            target_noise=0.1,
            noise_clip=0.5,
            policy_delay=2,
            critic_grad_clip=25.0,
            loss="pal",
            pal_alpha=0.4,
            pal_min_priority=1.0,
            time_augmentation=True,
            max_time=1000,
        )
        return dataclasses.replace(base, **overrides)

    @classmethod
    def fast(cls, **overrides: Any) -> TD3Config:
        """``paper()`` with 256-256 critics instead of 1024-1024, for CPU runs.

        The 1024-wide critics hold ~90% of the paper preset's parameters and compute, so they
        are the one lever that matters on a CPU (several times more updates per second).
        Everything else, PAL loss included, is kept: PAL costs the same as MSE per update, and
        changing a single ingredient keeps results comparable with the paper preset.
        """
        return cls.paper(**{"critic_hidden": (256, 256), **overrides})


def ddpg_config(base: TD3Config | None = None, **overrides: Any) -> TD3Config:
    """DDPG as a TD3 configuration, in the spirit of Fujimoto's "OurDDPG".

    Removes TD3's three ingredients from ``base`` (default ``TD3Config.paper()``): a single
    critic (no clipped double Q), no target policy smoothing, and actor/target updates at every
    step (policy_delay 1). Everything else (network sizes, loss, tau, noise, time augmentation)
    stays as in ``base``, so a DDPG run differs from its TD3 counterpart only in those three.
    ``ddpg_config(TD3Config())`` is OurDDPG's algorithm (MSE, tau 0.005, batch 256) with TD3's
    256-256 networks (OurDDPG's own are 400-300).
    """
    base = TD3Config.paper() if base is None else base
    cfg = dataclasses.replace(base, num_critics=1, target_noise=0.0, noise_clip=0.0, policy_delay=1)
    return dataclasses.replace(cfg, **overrides)


class TD3State(flax.struct.PyTreeNode):
    """Everything TD3 learns or needs to continue learning (a pytree)."""

    actor_params: Params
    critic_params: Params
    """Parameters of all critics, stacked on a leading axis of size num_critics."""
    actor_target: Params
    critic_target: Params
    actor_opt_state: optax.OptState
    critic_opt_state: optax.OptState
    obs_mean: jax.Array
    """(obs_dim,) networks see (obs - obs_mean) / obs_std."""
    obs_std: jax.Array
    """(obs_dim,)"""
    normalizer_set: jax.Array
    """() bool, True once ``set_normalizer`` has been called."""
    step: jax.Array
    """() int32, critic updates done so far."""
    key: jax.Array
    """PRNG key consumed by ``update``."""


class TD3(NamedTuple):
    """The functions of a TD3 agent built by ``make_td3`` (config closed over)."""

    config: TD3Config
    obs_dim: int
    action_dim: int
    max_action: float
    init: Callable[[int], TD3State]
    """init(seed) -> state with fresh parameters and an identity normaliser."""
    act: Callable[..., jax.Array]
    """act(state or Policy, obs (..., obs_dim), key=None) -> action (..., action_dim). key None:
    deterministic; else Gaussian exploration noise, clipped to [-max_action, max_action]."""
    update: Callable[..., tuple[TD3State, dict[str, jax.Array]]]
    """update(state, data: ReplayData, size, num_updates) -> (state, metrics)."""
    run_updates: Callable[..., tuple[Any, tuple[jax.Array, ...]]]
    """run_updates(step, state, data, size, num_updates, updates_done) -> (state, outputs):
    ``num_updates`` applications of ``step`` (``update_step`` or a wrapper of it, on any state
    with a ``key``) in one ``lax.scan``, as ``update`` runs them (``delayed_updates``; the actor
    trained on every ``policy_delay``-th counting from ``updates_done``)."""
    metrics_of: Callable[[tuple[jax.Array, ...], TD3State], dict[str, jax.Array]]
    """metrics_of(stacked outputs, final state) -> the scalar metrics ``update`` reports."""
    update_step: Callable[..., tuple[TD3State, tuple[jax.Array, ...]]]
    """update_step(state, batch, key, train_actor=None, actor_term=None) -> (state, outputs):
    one update on one batch, not jitted, for updates that wrap it (a learned reward relabels
    ``batch.reward`` first; ``actor_term`` adds to the actor loss: ``ActorTerm``). Outputs:
    (critic loss, actor loss, mean Q, actor trained); ``td3_metrics`` reduces them."""
    set_normalizer: Callable[[TD3State, ArrayLike, ArrayLike], TD3State]
    """set_normalizer(state, mean, std) -> state; allowed once."""
    q_values: Callable[[TD3State, jax.Array, jax.Array], jax.Array]
    """q_values(state, obs (..., obs_dim), action (..., action_dim)) -> (num_critics, ...): the
    online critics' values, observations normalised as in training (for diagnostics)."""


class _Networks(NamedTuple):
    """TD3's modules and optimisers, built once from the config (static)."""

    actor: DeterministicActor
    critic: CriticEnsemble
    first_critic: CriticEnsemble
    """The first critic alone (the actor loss's Q): parameters sliced from the ensemble."""
    actor_opt: optax.GradientTransformation
    critic_opt: optax.GradientTransformation
    max_action: float


ActorTerm = Callable[[Callable[[jax.Array], jax.Array]], jax.Array]
"""An extra actor-loss term: ``term(policy) -> scalar``, where ``policy(obs) -> action`` applies
the actor being trained (observations raw: normalised inside) and is differentiable in its
parameters. A recipe builds it per update from its own inputs (e.g. OPOLO's inverse-dynamics
actions of expert transitions)."""


def _init_state(nets: _Networks, obs_dim: int, action_dim: int, seed: int) -> TD3State:
    key, k_actor, k_critic = jax.random.split(jax.random.PRNGKey(seed), 3)
    obs = jnp.zeros((1, obs_dim), jnp.float32)
    action = jnp.zeros((1, action_dim), jnp.float32)
    actor_params = nets.actor.init(k_actor, obs)
    critic_params = nets.critic.init(k_critic, obs, action)
    return TD3State(
        actor_params=actor_params,
        critic_params=critic_params,
        actor_target=actor_params,
        critic_target=critic_params,
        actor_opt_state=nets.actor_opt.init(actor_params),
        critic_opt_state=nets.critic_opt.init(critic_params),
        obs_mean=jnp.zeros(obs_dim, jnp.float32),
        obs_std=jnp.ones(obs_dim, jnp.float32),
        normalizer_set=jnp.array(False),
        step=jnp.array(0, jnp.int32),
        key=key,
    )


def _normalize(state: TD3State | Policy, obs: jax.Array) -> jax.Array:
    return (obs - state.obs_mean) / state.obs_std


def _critic_inputs(
    cfg: TD3Config, batch: ReplayData, key: jax.Array
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The critic's (obs, next_obs, not_done) of a batch, time-augmented as configured."""
    if cfg.time_augmentation and cfg.time_augmentation_scheme == "next_only":
        return batch.obs, redraw_next_time(key, batch.next_obs, cfg.max_time), batch.not_done
    if cfg.time_augmentation:  # "finite_horizon"
        return augment_time(key, batch.obs, batch.next_obs, cfg.max_time)
    return batch.obs, batch.next_obs, batch.not_done


def _critic_step(
    nets: _Networks, cfg: TD3Config, state: TD3State, batch: ReplayData, key: jax.Array
) -> tuple[Params, optax.OptState, jax.Array, jax.Array]:
    """One critic update: TD target from the target networks with target policy smoothing.
    Returns (critic_params, critic_opt_state, loss, mean Q)."""
    k_noise, k_time = jax.random.split(key)
    critic_obs, next_obs, not_done = _critic_inputs(cfg, batch, k_time)
    critic_obs_n = _normalize(state, critic_obs)
    next_obs_n = _normalize(state, next_obs)
    max_action = nets.max_action
    next_action = nets.actor.apply(state.actor_target, next_obs_n)
    if cfg.target_noise > 0:
        noise = jax.random.normal(k_noise, next_action.shape) * (cfg.target_noise * max_action)
        noise = jnp.clip(noise, -cfg.noise_clip * max_action, cfg.noise_clip * max_action)
        next_action = jnp.clip(next_action + noise, -max_action, max_action)
    next_q = jnp.min(nets.critic.apply(state.critic_target, next_obs_n, next_action), axis=0)
    target = jax.lax.stop_gradient(batch.reward + cfg.gamma * not_done * next_q)

    def loss_fn(params: Params) -> tuple[jax.Array, jax.Array]:
        q = nets.critic.apply(params, critic_obs_n, batch.action)  # (num_critics, B)
        loss = critic_loss(q - target, cfg.loss, cfg.pal_alpha, cfg.pal_min_priority)
        return loss, jnp.mean(q)

    (loss, q_mean), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.critic_params)
    updates, opt_state = nets.critic_opt.update(grads, state.critic_opt_state, state.critic_params)
    return optax.apply_updates(state.critic_params, updates), opt_state, loss, q_mean


def _actor_step(
    nets: _Networks,
    cfg: TD3Config,
    state: TD3State,
    critic_params: Params,
    obs: jax.Array,
    actor_term: ActorTerm | None,
) -> tuple[Params, optax.OptState, Params, Params, jax.Array]:
    """The delayed actor update (maximise the first critic's Q at the recorded time, plus
    ``actor_term``) and the targets' Polyak step. Returns (actor_params, actor_opt_state,
    actor_target, critic_target, actor loss)."""
    obs_n = _normalize(state, obs)
    q1_params = jax.tree.map(lambda p: p[:1], critic_params)

    def loss_fn(params: Params) -> jax.Array:
        action = nets.actor.apply(params, obs_n)
        loss = -jnp.mean(nets.first_critic.apply(q1_params, obs_n, action))
        if actor_term is not None:
            loss = loss + actor_term(lambda o: nets.actor.apply(params, _normalize(state, o)))
        return loss

    loss, grads = jax.value_and_grad(loss_fn)(state.actor_params)
    updates, opt_state = nets.actor_opt.update(grads, state.actor_opt_state, state.actor_params)
    actor_params = optax.apply_updates(state.actor_params, updates)
    actor_target = optax.incremental_update(actor_params, state.actor_target, cfg.tau)
    critic_target = optax.incremental_update(critic_params, state.critic_target, cfg.tau)
    return actor_params, opt_state, actor_target, critic_target, loss


def _update_step(
    nets: _Networks,
    cfg: TD3Config,
    state: TD3State,
    batch: ReplayData,
    key: jax.Array,
    train_actor: bool | None = None,
    actor_term: ActorTerm | None = None,
) -> tuple[TD3State, tuple[jax.Array, jax.Array, jax.Array, jax.Array]]:
    """One critic update and, every ``policy_delay``-th update (Fujimoto: on update numbers
    delay, 2 * delay, ...), the actor's and the targets'. ``train_actor``: None decides by
    ``state.step`` at run time (a ``cond``); True / False fixes it. Returns the new state and
    (critic loss, actor loss (0 where not trained), mean Q, whether the actor was trained)."""
    critic_params, critic_opt_state, c_loss, q_mean = _critic_step(nets, cfg, state, batch, key)

    def actor_step(_: None):
        return _actor_step(nets, cfg, state, critic_params, batch.obs, actor_term)

    def skip(_: None):
        kept = (state.actor_params, state.actor_opt_state, state.actor_target, state.critic_target)
        return (*kept, jnp.zeros((), jnp.float32))

    do_actor, outs = delayed(train_actor, state.step, cfg.policy_delay, actor_step, skip)
    actor_params, actor_opt_state, actor_target, critic_target, a_loss = outs
    new_state = state.replace(
        actor_params=actor_params,
        critic_params=critic_params,
        actor_target=actor_target,
        critic_target=critic_target,
        actor_opt_state=actor_opt_state,
        critic_opt_state=critic_opt_state,
        step=state.step + 1,
    )
    return new_state, (c_loss, a_loss, q_mean, do_actor)


def delayed(
    train_actor: bool | None,
    updates_done: jax.Array,
    policy_delay: int,
    actor_step: Callable[[None], Any],
    skip: Callable[[None], Any],
) -> tuple[jax.Array, Any]:
    """The actor's part of one update: ``actor_step(None)`` on update numbers policy_delay,
    2 * policy_delay, ... (``updates_done`` before this one), else ``skip(None)`` (the same
    outputs, unchanged). ``train_actor`` True / False fixes the choice statically (no ``cond``);
    None decides at run time. Returns (whether the actor was trained, the outputs)."""
    if train_actor is None:
        do_actor = (updates_done + 1) % policy_delay == 0
        return do_actor, jax.lax.cond(do_actor, actor_step, skip, None)
    return jnp.array(train_actor), actor_step(None) if train_actor else skip(None)


def delayed_updates(
    update_step: Callable[..., tuple[Any, Any]],
    policy_delay: int,
    updates_done: jax.Array,
    state: Any,
    data: ReplayData,
    size: jax.Array | int,
    num_updates: int,
    batch_size: int,
) -> tuple[Any, Any]:
    """``num_updates`` applications of ``update_step(state, batch, key, train_actor=...)`` in
    one ``lax.scan`` (batches and keys as ``scan_updates`` draws them), the actor trained on
    every ``policy_delay``-th update counting from ``updates_done`` (the updates before these).

    Whole groups of ``policy_delay`` updates, the actor trained in the last, need no run-time
    ``cond`` (which XLA schedules poorly on a CPU); they apply when the count is aligned with
    the delay (always with delay 1; with 2, when every episode is of even length); otherwise
    each update decides with a ``cond`` (``train_actor=None``). Used by TD3's ``update`` and by
    updates that wrap TD3's step (``ilfo.composition.learned``)."""
    delay = policy_delay
    group = [functools.partial(update_step, train_actor=False)] * (delay - 1)
    group.append(functools.partial(update_step, train_actor=True))

    def grouped(state: Any):
        return scan_update_groups(group, state, data, size, num_updates // delay, batch_size)

    def one_by_one(state: Any):
        return scan_updates(update_step, state, data, size, num_updates, batch_size)

    if num_updates % delay:
        return one_by_one(state)
    if delay == 1:
        return grouped(state)
    return jax.lax.cond(updates_done % delay == 0, grouped, one_by_one, state)


def td3_metrics(outs: tuple[jax.Array, ...]) -> dict[str, jax.Array]:
    """Scalar metrics of stacked ``update_step`` outputs: mean critic loss, mean actor loss
    over the updates that trained the actor, mean Q."""
    c_loss, a_loss, q_mean, did_actor = outs[:4]
    n_actor = jnp.sum(did_actor)
    return {
        "critic_loss": jnp.mean(c_loss),
        "actor_loss": jnp.sum(jnp.where(did_actor, a_loss, 0.0)) / jnp.maximum(n_actor, 1),
        "q_mean": jnp.mean(q_mean),
    }


def _networks(cfg: TD3Config, action_dim: int, max_action: float) -> _Networks:
    return _Networks(
        actor=DeterministicActor(cfg.actor_hidden, action_dim, max_action, cfg.init_scheme),
        critic=CriticEnsemble(
            cfg.critic_hidden, cfg.num_critics, cfg.init_scheme, cfg.critic_layer_norm
        ),
        first_critic=CriticEnsemble(cfg.critic_hidden, 1, cfg.init_scheme, cfg.critic_layer_norm),
        actor_opt=optax.adam(cfg.lr_actor),
        critic_opt=make_optimizer(cfg.lr_critic, cfg.critic_grad_clip),
        max_action=max_action,
    )


def make_td3(
    config: TD3Config, obs_dim: int, action_dim: int, max_action: float | ArrayLike = 1.0
) -> TD3:
    """Build the pure functions of a TD3 agent.

    Args:
        config: hyperparameters.
        obs_dim: observation size, time feature included when ``config.time_augmentation``.
        action_dim: action size.
        max_action: bound of the symmetric action box [-max_action, max_action], the same for
            every dimension (as in MuJoCo tasks).
    """
    cfg = config
    max_action = as_float_bound(max_action)
    if cfg.time_augmentation and obs_dim < 2:
        raise ValueError("time augmentation needs observations with a trailing time feature")
    nets = _networks(cfg, action_dim, max_action)

    @jax.jit
    def act(state: TD3State | Policy, obs: jax.Array, key: jax.Array | None = None) -> jax.Array:
        action = nets.actor.apply(state.actor_params, _normalize(state, obs))
        if key is None:
            return action
        noise = jax.random.normal(key, action.shape) * (cfg.exploration_noise * max_action)
        return jnp.clip(action + noise, -max_action, max_action)

    @jax.jit
    def q_values(state: TD3State, obs: jax.Array, action: jax.Array) -> jax.Array:
        return nets.critic.apply(state.critic_params, _normalize(state, obs), action)

    update_step = functools.partial(_update_step, nets, cfg)

    def update(
        state: TD3State, data: ReplayData, size: jax.Array | int, num_updates: int
    ) -> tuple[TD3State, dict[str, jax.Array]]:
        """Run ``num_updates`` TD3 updates in one jitted ``lax.scan``.

        Each update draws a uniform batch of ``config.batch_size`` transitions from slots
        ``[0, size)`` of ``data`` (a ``ReplayData``; arrays (N, ...)). ``size`` may change between
        calls without recompiling; ``num_updates`` is static. Returns the new state and metrics:
        mean critic loss, mean actor loss (over the updates that trained the actor) and mean Q of
        the batches (all scalars)."""
        state, outs = delayed_updates(
            update_step,
            cfg.policy_delay,
            state.step,
            state,
            data,
            size,
            num_updates,
            cfg.batch_size,
        )
        return state, td3_metrics(outs)

    def run_updates(step, state, data, size, num_updates: int, updates_done):
        return delayed_updates(
            step, cfg.policy_delay, updates_done, state, data, size, num_updates, cfg.batch_size
        )

    return TD3(
        config=cfg,
        obs_dim=obs_dim,
        action_dim=action_dim,
        max_action=max_action,
        init=functools.partial(_init_state, nets, obs_dim, action_dim),
        act=act,
        update=jax.jit(update, static_argnames="num_updates"),
        update_step=update_step,
        run_updates=run_updates,
        metrics_of=lambda outs, state: td3_metrics(outs),
        set_normalizer=make_normalizer_setter(obs_dim, cfg.time_augmentation),
        q_values=q_values,
    )
