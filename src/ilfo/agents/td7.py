"""TD7 (Fujimoto, Chang, Smith, Gu, Precup, Meger, NeurIPS 2023: "For SALE: State-Action
Representation Learning for Deep Reinforcement Learning"), for ilfo's loop.

What TD7 adds to TD3, each a piece of ``update_step``:

- **SALE**: a state encoder ``zs = f(s)`` and a state-action encoder ``zsa = g(zs, a)``, trained
  on the learner's own transitions to predict the next state's embedding
  (``encoder_loss``: ``g(f(s), a)`` against ``stop_gradient(f(s'))``). The actor sees
  ``[AvgL1Norm(W s), zs]``, the critics ``[AvgL1Norm(W (s, a)), zsa, zs]``; both read the
  embeddings of a *fixed* copy of the encoder, which the trained one replaces every
  ``target_update_every`` updates (and its previous value becomes the targets' encoder).
- **Hard target updates**: actor, critics and the targets' encoder copied every
  ``target_update_every`` updates (no Polyak averaging).
- **Value clipping**: TD targets' bootstrapped values clipped to the range of the targets seen
  during the previous target period (``clip_target``).
- **LAP**, as its uniform-sampling equivalent: the PAL loss
  (``ilfo.agents.critic_targets.pal_loss``, the same authors' proof that PAL with uniform
  sampling has LAP's expected gradient), so the replay buffer stays uniform.

- **Policy checkpoints** (``policy_checkpoints``, on as in the authors' code): evaluations use
  the checkpoint policy, the one whose minimum return over an assessment of its training
  episodes is the best recent one, while the actor explores as trained. They live in the loop,
  which defers the updates during an assessment (``ilfo.agents.policy_checkpoints``: the
  schedule; ``ilfo.training.learners.PolicyCheckpoints``); ``update`` is the same either way.

The authors' code (sfujim/TD7) was read for the architecture and schedules; this is ilfo's own
JAX.

Time augmentation (ilfo's fixed-horizon protocol) applies to the critic's samples as in TD3
(``ilfo.agents.critic_targets.augment_time``); the encoder and the actor use the recorded times.

Usage::

    agent = make_td7(TD7Config(), obs_dim=12, action_dim=3, max_action=1.0)
    state = agent.init(seed=0)
    state, metrics = agent.update(state, buffer.data, buffer.size, num_updates=1000)
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import flax
import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from numpy.typing import ArrayLike

from ilfo.agents._common import (
    Policy,
    as_float_bound,
    make_normalizer_setter,
    make_optimizer,
)
from ilfo.agents.critic_targets import TimeAugmentationScheme, augment_time, pal_loss
from ilfo.agents.td3 import delayed_updates
from ilfo.networks import ArrayModule, dense, ensemble
from ilfo.ranges import (
    batch,
    check_fields,
    count,
    fraction,
    learning_rate,
    non_negative,
    positive,
    width,
)
from ilfo.replay import ReplayData

__all__ = [
    "TD7",
    "TD7Config",
    "TD7State",
    "avg_l1_norm",
    "clip_target",
    "encoder_loss",
    "make_td7",
]

Params = Any


@dataclasses.dataclass(frozen=True)
class TD7Config:
    """Hyperparameters of TD7. The defaults are the authors' (sfujim/TD7 ``Hyperparameters``),
    with the PAL loss standing in for LAP's prioritised sampling."""

    zs_dim: int = width(256)
    """Size of the embeddings zs and zsa."""
    encoder_hidden: int = width(256)
    """Width of the encoders' two hidden layers (ELU)."""
    actor_hidden: int = width(256)
    """Width of the actor's input projection and its two hidden layers (ReLU)."""
    critic_hidden: int = width(256)
    """Width of each critic's input projection and its two hidden layers (ELU)."""
    num_critics: int = count(2)
    """Critics; the TD target takes their minimum, the actor maximises their mean."""
    batch_size: int = batch(256)
    """Transitions per gradient step."""
    gamma: float = fraction(0.99)
    """Discount factor."""
    lr_actor: float = learning_rate(3e-4)
    """Adam learning rate of the actor."""
    lr_critic: float = learning_rate(3e-4)
    """Adam learning rate of the critics."""
    lr_encoder: float = learning_rate(3e-4)
    """Adam learning rate of the encoders."""
    critic_grad_clip: float | None = positive(None)
    """Clip the critics' global gradient norm to this value; None = no clipping (the
    authors')."""
    exploration_noise: float = non_negative(0.1)
    """Std of the Gaussian noise added to actions when acting, in units of max_action."""
    target_noise: float = non_negative(0.2)
    """Std of the target policy smoothing noise, in units of max_action."""
    noise_clip: float = non_negative(0.5)
    """Target smoothing noise is clipped to +-noise_clip, in units of max_action."""
    policy_delay: int = count(2)
    """One actor update every policy_delay critic updates."""
    target_update_every: int = count(250)
    """Updates between hard copies of the targets and the fixed encoder."""
    value_clipping: bool = True
    """Clip the targets' bootstrapped values to the range of the previous period's targets."""
    pal_alpha: float = non_negative(0.4)
    """PAL/LAP exponent alpha (priority = max(|td|, min_priority)^alpha)."""
    pal_min_priority: float = positive(1.0)
    """PAL/LAP minimum priority: the loss is quadratic below it."""
    time_augmentation: bool = True
    """Observations end with a time feature; the critic's samples get random times, as
    ``time_augmentation_scheme`` says. Applied only where observations carry the feature
    (fixed-horizon runs: the trainer decides)."""
    time_augmentation_scheme: TimeAugmentationScheme = "finite_horizon"
    """As TD3's (``ilfo.agents.td3.TD3Config.time_augmentation_scheme``); only
    "finite_horizon" is built for TD7."""
    max_time: int = count(1000)
    """Scale of the time feature (the horizon); set by the trainer in ``ilfo train``."""
    policy_checkpoints: bool = True
    """Evaluate with TD7's checkpoint policy (the authors' ``use_checkpoints``): updates wait
    while the current policy is assessed over its training episodes, and it replaces the
    checkpoint where its minimum return is at least the checkpoint's; the run's evaluations,
    best and final policies are the checkpoint's. The return is the one the agent learns from
    (under an imitation reward its sum, the proxy return). Off: updates after every episode,
    evaluations of the policy as trained."""
    checkpoint_max_episodes: int = count(20)
    """Episodes an assessment lasts at most once ``checkpoint_early_updates`` have run (one
    before); it ends at the first whose return falls below the checkpoint's minimum."""
    checkpoint_early_updates: int = count(750_000, low=0)
    """Updates during which assessments last one episode (the authors'
    ``steps_before_checkpointing``: 75% of a 1M-step run); as the updates pass it, the
    checkpoint's minimum return is scaled by ``checkpoint_reset_weight``."""
    checkpoint_reset_weight: float = fraction(0.9)
    """What the checkpoint's minimum return is multiplied by as the updates pass
    ``checkpoint_early_updates``, so that a policy assessed over many episodes can replace one
    that one episode assessed."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)
        if self.time_augmentation_scheme != "finite_horizon":
            raise ValueError("TD7 supports time_augmentation_scheme 'finite_horizon' only")

    @classmethod
    def fast(cls, **overrides: Any) -> TD7Config:
        """TD7 sized for one CPU core: every width 128 (embeddings included) and batches of
        100, the OOPS paper's TD3 batch. About 8x the authors' updates per second here
        (docs/benchmarks.md, ``bench/agents.py``), so that a 1M-step run fits ~1.5 h of a core
        where the authors' sizes take ~7 h."""
        sizes = {"zs_dim": 128, "encoder_hidden": 128, "actor_hidden": 128, "critic_hidden": 128}
        return cls(**{**sizes, "batch_size": 100, **overrides})


def avg_l1_norm(x: jax.Array, eps: float = 1e-8) -> jax.Array:
    """x divided by the mean of its absolute values over the last axis (SALE's AvgL1Norm)."""
    return x / jnp.maximum(jnp.mean(jnp.abs(x), axis=-1, keepdims=True), eps)


def _torch_dense(features: int, fan_in: int) -> nn.Dense:
    return dense(features, fan_in, "torch")  # the authors' code is PyTorch's nn.Linear


class Encoder(ArrayModule):
    """SALE's encoders: ``zs(s)`` (ELU, ELU, linear, AvgL1Norm) and ``zsa(zs, a)`` (ELU, ELU,
    linear)."""

    obs_dim: int
    action_dim: int
    zs_dim: int
    hidden: int

    def setup(self) -> None:
        h = self.hidden
        self.zs_layers = [
            _torch_dense(h, self.obs_dim),
            _torch_dense(h, h),
            _torch_dense(self.zs_dim, h),
        ]
        self.zsa_layers = [
            _torch_dense(h, self.zs_dim + self.action_dim),
            _torch_dense(h, h),
            _torch_dense(self.zs_dim, h),
        ]

    def zs(self, obs: jax.Array) -> jax.Array:
        x = nn.elu(self.zs_layers[0](obs))
        x = nn.elu(self.zs_layers[1](x))
        return avg_l1_norm(self.zs_layers[2](x))

    def zsa(self, zs: jax.Array, action: jax.Array) -> jax.Array:
        x = nn.elu(self.zsa_layers[0](jnp.concatenate([zs, action], axis=-1)))
        x = nn.elu(self.zsa_layers[1](x))
        return self.zsa_layers[2](x)

    def __call__(self, obs: jax.Array, action: jax.Array) -> jax.Array:
        return self.zsa(self.zs(obs), action)


class Actor(ArrayModule):
    """(obs, zs) -> tanh(...) in [-1, 1]: ``[AvgL1Norm(W obs), zs]``, ReLU, ReLU, tanh."""

    action_dim: int
    hidden: int

    @nn.compact
    def __call__(self, obs: jax.Array, zs: jax.Array) -> jax.Array:
        x = avg_l1_norm(_torch_dense(self.hidden, obs.shape[-1])(obs))
        x = jnp.concatenate([x, zs], axis=-1)
        x = nn.relu(_torch_dense(self.hidden, x.shape[-1])(x))
        x = nn.relu(_torch_dense(self.hidden, x.shape[-1])(x))
        return jnp.tanh(_torch_dense(self.action_dim, x.shape[-1])(x))


class _Critic(ArrayModule):
    hidden: int

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array, zsa: jax.Array, zs: jax.Array):
        sa = jnp.concatenate([obs, action], axis=-1)
        x = avg_l1_norm(_torch_dense(self.hidden, sa.shape[-1])(sa))
        x = jnp.concatenate([x, zsa, zs], axis=-1)
        x = nn.elu(_torch_dense(self.hidden, x.shape[-1])(x))
        x = nn.elu(_torch_dense(self.hidden, x.shape[-1])(x))
        return _torch_dense(1, x.shape[-1])(x)[..., 0]


class CriticEnsemble(ArrayModule):
    """``num_critics`` SALE critics at once: (obs, action, zsa, zs) -> Q (num_critics, ...)."""

    hidden: int
    num_critics: int

    @nn.compact
    def __call__(self, obs: jax.Array, action: jax.Array, zsa: jax.Array, zs: jax.Array):
        members = ensemble(_Critic, self.num_critics)
        return members(self.hidden, name="ensemble")(obs, action, zsa, zs)


class TD7State(flax.struct.PyTreeNode):
    """Everything TD7 learns or needs to continue learning (a pytree)."""

    actor_params: Params
    """What acting needs: {"actor": the actor, "encoder": the fixed encoder it reads}."""
    encoder_params: Params
    """The encoder being trained (it becomes the fixed one at each target update)."""
    critic_params: Params
    """All critics, stacked on a leading axis."""
    actor_target: Params
    """{"actor": the target actor, "encoder": the targets' encoder}."""
    critic_target: Params
    actor_opt_state: optax.OptState
    critic_opt_state: optax.OptState
    encoder_opt_state: optax.OptState
    target_range: jax.Array
    """(2,) [min, max] the bootstrapped values are clipped to (the previous period's)."""
    seen_range: jax.Array
    """(2,) [min, max] of the TD targets seen so far (becomes ``target_range`` at updates)."""
    obs_mean: jax.Array
    """(obs_dim,) networks see (obs - obs_mean) / obs_std."""
    obs_std: jax.Array
    normalizer_set: jax.Array
    step: jax.Array
    """() int32, updates done so far."""
    key: jax.Array


class TD7(NamedTuple):
    """The functions of a TD7 agent built by ``make_td7`` (config closed over)."""

    config: TD7Config
    obs_dim: int
    action_dim: int
    max_action: float
    init: Callable[[int], TD7State]
    """init(seed) -> state with fresh parameters and an identity normaliser."""
    act: Callable[..., jax.Array]
    """act(state or Policy, obs (..., obs_dim), key=None) -> action (..., action_dim)."""
    update: Callable[..., tuple[TD7State, dict[str, jax.Array]]]
    """update(state, data: ReplayData, size, num_updates) -> (state, metrics)."""
    update_step: Callable[..., tuple[TD7State, tuple[jax.Array, ...]]]
    """update_step(state, batch, key, train_actor=None) -> (state, outputs), not jitted:
    (critic loss, actor loss, mean Q, actor trained, encoder loss)."""
    set_normalizer: Callable[[TD7State, ArrayLike, ArrayLike], TD7State]
    q_values: Callable[[TD7State, jax.Array, jax.Array], jax.Array]
    """q_values(state, obs, action) -> (num_critics, ...) online critics' values."""


def encoder_loss(
    encoder: Encoder, params: Params, obs: jax.Array, action: jax.Array, next_obs: jax.Array
) -> jax.Array:
    """SALE's loss: mean squared error of ``zsa(zs(s), a)`` against ``stop_gradient(zs(s'))``,
    both from the encoder being trained (actions in [-1, 1])."""
    next_zs = jax.lax.stop_gradient(encoder.apply(params, next_obs, method=Encoder.zs))
    pred = encoder.apply(params, obs, action)
    return jnp.mean((pred - next_zs) ** 2)


def clip_target(value: jax.Array, target_range: jax.Array, enabled: bool) -> jax.Array:
    """TD7's value clipping: ``value`` clipped to ``target_range`` [min, max] where enabled."""
    return jnp.clip(value, target_range[0], target_range[1]) if enabled else value


class _Networks(NamedTuple):
    encoder: Encoder
    actor: Actor
    critic: CriticEnsemble
    actor_opt: optax.GradientTransformation
    critic_opt: optax.GradientTransformation
    encoder_opt: optax.GradientTransformation
    max_action: float


def _normalize(state: TD7State | Policy, obs: jax.Array) -> jax.Array:
    return (obs - state.obs_mean) / state.obs_std


def _policy_action(nets: _Networks, params: Params, obs_n: jax.Array) -> jax.Array:
    """The actor's action in [-1, 1] from normalised observations, through its encoder."""
    zs = nets.encoder.apply(params["encoder"], obs_n, method=Encoder.zs)
    return nets.actor.apply(params["actor"], obs_n, zs)


def _init_state(nets: _Networks, obs_dim: int, action_dim: int, seed: int) -> TD7State:
    key, k_enc, k_actor, k_critic = jax.random.split(jax.random.PRNGKey(seed), 4)
    obs = jnp.zeros((1, obs_dim), jnp.float32)
    action = jnp.zeros((1, action_dim), jnp.float32)
    zs_dim = nets.encoder.zs_dim
    zs = jnp.zeros((1, zs_dim), jnp.float32)
    encoder = nets.encoder.init(k_enc, obs, action)
    actor = {"actor": nets.actor.init(k_actor, obs, zs), "encoder": encoder}
    critic = nets.critic.init(k_critic, obs, action, zs, zs)
    return TD7State(
        actor_params=actor,
        encoder_params=encoder,
        critic_params=critic,
        actor_target=actor,
        critic_target=critic,
        actor_opt_state=nets.actor_opt.init(actor["actor"]),
        critic_opt_state=nets.critic_opt.init(critic),
        encoder_opt_state=nets.encoder_opt.init(encoder),
        target_range=jnp.zeros(2, jnp.float32),
        seen_range=jnp.array([jnp.inf, -jnp.inf], jnp.float32),
        obs_mean=jnp.zeros(obs_dim, jnp.float32),
        obs_std=jnp.ones(obs_dim, jnp.float32),
        normalizer_set=jnp.array(False),
        step=jnp.array(0, jnp.int32),
        key=key,
    )


def _encoder_step(nets: _Networks, state: TD7State, obs_n, action, next_obs_n):
    loss, grads = jax.value_and_grad(functools.partial(encoder_loss, nets.encoder))(
        state.encoder_params, obs_n, action, next_obs_n
    )
    updates, opt_state = nets.encoder_opt.update(
        grads, state.encoder_opt_state, state.encoder_params
    )
    return optax.apply_updates(state.encoder_params, updates), opt_state, loss


def _critic_step(
    nets: _Networks, cfg: TD7Config, state: TD7State, batch: ReplayData, key: jax.Array
):
    """One critic update. Returns (critic params, opt state, loss, mean Q, targets' range)."""
    k_noise, k_time = jax.random.split(key)
    obs, next_obs, not_done = batch.obs, batch.next_obs, batch.not_done
    if cfg.time_augmentation:
        obs, next_obs, not_done = augment_time(k_time, obs, next_obs, cfg.max_time)
    obs_n, next_obs_n = _normalize(state, obs), _normalize(state, next_obs)
    action = batch.action / nets.max_action
    target_encoder = state.actor_target["encoder"]
    next_zs = nets.encoder.apply(target_encoder, next_obs_n, method=Encoder.zs)
    next_action = nets.actor.apply(state.actor_target["actor"], next_obs_n, next_zs)
    noise = jnp.clip(
        jax.random.normal(k_noise, next_action.shape) * cfg.target_noise,
        -cfg.noise_clip,
        cfg.noise_clip,
    )
    next_action = jnp.clip(next_action + noise, -1.0, 1.0)
    next_zsa = nets.encoder.apply(target_encoder, next_zs, next_action, method=Encoder.zsa)
    next_q = jnp.min(
        nets.critic.apply(state.critic_target, next_obs_n, next_action, next_zsa, next_zs), axis=0
    )
    next_q = clip_target(next_q, state.target_range, cfg.value_clipping)
    target = jax.lax.stop_gradient(batch.reward + cfg.gamma * not_done * next_q)
    fixed = state.actor_params["encoder"]
    zs = nets.encoder.apply(fixed, obs_n, method=Encoder.zs)
    zsa = nets.encoder.apply(fixed, zs, action, method=Encoder.zsa)

    def loss_fn(params: Params) -> tuple[jax.Array, jax.Array]:
        q = nets.critic.apply(params, obs_n, action, zsa, zs)
        return pal_loss(q - target, cfg.pal_alpha, cfg.pal_min_priority), jnp.mean(q)

    (loss, q_mean), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.critic_params)
    updates, opt_state = nets.critic_opt.update(grads, state.critic_opt_state, state.critic_params)
    seen = jnp.array([jnp.min(target), jnp.max(target)])
    return optax.apply_updates(state.critic_params, updates), opt_state, loss, q_mean, seen


def _actor_step(nets: _Networks, state: TD7State, critic_params: Params, obs_n: jax.Array):
    """The delayed actor update: maximise the critics' mean Q through the fixed encoder."""
    fixed = state.actor_params["encoder"]
    zs = nets.encoder.apply(fixed, obs_n, method=Encoder.zs)

    def loss_fn(actor: Params) -> jax.Array:
        action = nets.actor.apply(actor, obs_n, zs)
        zsa = nets.encoder.apply(fixed, zs, action, method=Encoder.zsa)
        return -jnp.mean(nets.critic.apply(critic_params, obs_n, action, zsa, zs))

    loss, grads = jax.value_and_grad(loss_fn)(state.actor_params["actor"])
    updates, opt_state = nets.actor_opt.update(
        grads, state.actor_opt_state, state.actor_params["actor"]
    )
    return optax.apply_updates(state.actor_params["actor"], updates), opt_state, loss


def _refresh_targets(state: TD7State) -> TD7State:
    """TD7's target update: targets <- online, targets' encoder <- fixed encoder, fixed encoder
    <- trained encoder, clipping range <- the range seen."""
    return state.replace(
        actor_target={
            "actor": state.actor_params["actor"],
            "encoder": state.actor_params["encoder"],
        },
        critic_target=state.critic_params,
        actor_params={"actor": state.actor_params["actor"], "encoder": state.encoder_params},
        target_range=state.seen_range,
    )


def _update_step(
    nets: _Networks,
    cfg: TD7Config,
    state: TD7State,
    batch: ReplayData,
    key: jax.Array,
    train_actor: bool | None = None,
) -> tuple[TD7State, tuple[jax.Array, ...]]:
    """One TD7 update: the encoder, the critics, every ``policy_delay``-th update the actor,
    and every ``target_update_every``-th the hard target copies. Returns the new state and
    (critic loss, actor loss (0 where not trained), mean Q, actor trained, encoder loss)."""
    obs_n, next_obs_n = _normalize(state, batch.obs), _normalize(state, batch.next_obs)
    action = batch.action / nets.max_action
    encoder, encoder_opt_state, e_loss = _encoder_step(nets, state, obs_n, action, next_obs_n)
    critic, critic_opt_state, c_loss, q_mean, seen = _critic_step(nets, cfg, state, batch, key)

    def actor_step(_: None):
        return _actor_step(nets, state, critic, obs_n)

    def skip(_: None):
        return state.actor_params["actor"], state.actor_opt_state, jnp.zeros((), jnp.float32)

    if train_actor is None:
        do_actor = (state.step + 1) % cfg.policy_delay == 0
        actor, actor_opt_state, a_loss = jax.lax.cond(do_actor, actor_step, skip, None)
    else:
        do_actor = jnp.array(train_actor)
        actor, actor_opt_state, a_loss = actor_step(None) if train_actor else skip(None)
    new_state = state.replace(
        actor_params={"actor": actor, "encoder": state.actor_params["encoder"]},
        encoder_params=encoder,
        critic_params=critic,
        actor_opt_state=actor_opt_state,
        critic_opt_state=critic_opt_state,
        encoder_opt_state=encoder_opt_state,
        seen_range=jnp.array(
            [jnp.minimum(state.seen_range[0], seen[0]), jnp.maximum(state.seen_range[1], seen[1])]
        ),
        step=state.step + 1,
    )
    refresh = new_state.step % cfg.target_update_every == 0
    new_state = jax.lax.cond(refresh, _refresh_targets, lambda s: s, new_state)
    return new_state, (c_loss, a_loss, q_mean, do_actor, e_loss)


def td7_metrics(outs: Sequence[jax.Array]) -> dict[str, jax.Array]:
    """Scalar metrics of stacked ``update_step`` outputs."""
    c_loss, a_loss, q_mean, did_actor, e_loss = outs
    n_actor = jnp.sum(did_actor)
    return {
        "critic_loss": jnp.mean(c_loss),
        "actor_loss": jnp.sum(jnp.where(did_actor, a_loss, 0.0)) / jnp.maximum(n_actor, 1),
        "q_mean": jnp.mean(q_mean),
        "encoder_loss": jnp.mean(e_loss),
    }


def make_td7(
    config: TD7Config, obs_dim: int, action_dim: int, max_action: float | ArrayLike = 1.0
) -> TD7:
    """Build the pure functions of a TD7 agent (``obs_dim`` includes the time feature where
    ``config.time_augmentation``; actions lie in [-max_action, max_action])."""
    cfg = config
    max_action = as_float_bound(max_action)
    if cfg.time_augmentation and obs_dim < 2:
        raise ValueError("time augmentation needs observations with a trailing time feature")
    nets = _Networks(
        encoder=Encoder(obs_dim, action_dim, cfg.zs_dim, cfg.encoder_hidden),
        actor=Actor(action_dim, cfg.actor_hidden),
        critic=CriticEnsemble(cfg.critic_hidden, cfg.num_critics),
        actor_opt=optax.adam(cfg.lr_actor),
        critic_opt=make_optimizer(cfg.lr_critic, cfg.critic_grad_clip),
        encoder_opt=optax.adam(cfg.lr_encoder),
        max_action=max_action,
    )

    @jax.jit
    def act(state: TD7State | Policy, obs: jax.Array, key: jax.Array | None = None) -> jax.Array:
        action = _policy_action(nets, state.actor_params, _normalize(state, obs))
        if key is not None:
            action = jnp.clip(
                action + jax.random.normal(key, action.shape) * cfg.exploration_noise, -1.0, 1.0
            )
        return action * max_action

    @jax.jit
    def q_values(state: TD7State, obs: jax.Array, action: jax.Array) -> jax.Array:
        obs_n, action = _normalize(state, obs), action / max_action
        fixed = state.actor_params["encoder"]
        zs = nets.encoder.apply(fixed, obs_n, method=Encoder.zs)
        zsa = nets.encoder.apply(fixed, zs, action, method=Encoder.zsa)
        return nets.critic.apply(state.critic_params, obs_n, action, zsa, zs)

    update_step = functools.partial(_update_step, nets, cfg)

    def update(
        state: TD7State, data: ReplayData, size: jax.Array | int, num_updates: int
    ) -> tuple[TD7State, dict[str, jax.Array]]:
        """``num_updates`` TD7 updates in one jitted ``lax.scan`` on uniform batches from slots
        [0, size) of ``data``; ``num_updates`` is static."""
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
        return state, td7_metrics(outs)

    return TD7(
        config=cfg,
        obs_dim=obs_dim,
        action_dim=action_dim,
        max_action=max_action,
        init=functools.partial(_init_state, nets, obs_dim, action_dim),
        act=act,
        update=jax.jit(update, static_argnames="num_updates"),
        update_step=update_step,
        set_normalizer=make_normalizer_setter(obs_dim, cfg.time_augmentation),
        q_values=q_values,
    )
