"""OPOLO (Zhu, Lin, Dai, Zhou, NeurIPS 2020): off-policy imitation learning from observations.

Follows the authors' TD3-based code (illidanlab/opolo-code ``td3/td3opolo.py``, hyperparams
``opolo.yml``; docs/reproduction.md has the table of where ilfo departs). Its parts:

- the (s, s') discriminator's reward -log(1 - D(s, s')), computed for each replay batch with
  the discriminator's current parameters (``ilfo.rewards.Discriminator``; trained 10 steps
  every 500 updates on replay and expert transitions);
- twin critics trained on J0 + 0.5 sum_i E[(y - Q_i(s, a))^2], with the TD target
  y = r + gamma * min_i Qtarget_i(s', pi(s')) (the online actor at s', no target smoothing)
  and the DICE-style "initial state" term J0 = 2 alpha (1 - gamma) E_s[min_i Q_i(s, pi(s))],
  s drawn from the replay batch, as the authors' code approximates the initial distribution;
- the actor, every ``policy_delay`` updates, minimising -J0 + pi_reg_coef *
  E[(a_hat - pi(s_E))^2]: a_hat = IDM(s_E, s_E') is the inverse dynamics model's action for
  an expert transition (no gradient into the model), so the policy is regularised towards
  the actions that the learner's own dynamics say the expert took;
- the inverse dynamics model (``ilfo.agents.inverse_dynamics``) trained on the learner's replay
  transitions: ``idm_pretrain_steps`` before the first update, then ``idm_steps`` every
  ``idm_every`` updates;
- critic targets by Polyak averaging on the actor's updates (there is no target actor).

Both gradients of an update are taken at the parameters before it (the authors' one
``sess.run``): the actor's J0 uses the critics of before their step.
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
)
from ilfo.agents.inverse_dynamics import (
    InverseDynamics,
    InverseDynamicsConfig,
    InverseDynamicsState,
)
from ilfo.agents.td3 import delayed, delayed_updates
from ilfo.networks import CriticEnsemble, DeterministicActor, InitName
from ilfo.ranges import (
    batch,
    check_fields,
    count,
    fraction,
    learning_rate,
    non_negative,
    widths,
)
from ilfo.replay import ReplayData, sample_batch
from ilfo.rewards.learned import RewardSchedule, env_observations, reward_steps

__all__ = ["OPOLO", "OPOLOConfig", "OPOLOState", "make_opolo"]

Params = Any


@dataclasses.dataclass(frozen=True)
class OPOLOConfig:
    """OPOLO's hyperparameters. Defaults: the authors' MuJoCo settings (opolo.yml for
    HalfCheetah, Walker2d and Ant; for Hopper the authors use lr 1e-4, alpha 0.01 and
    pi_reg_coef 0.01: ``OPOLOConfig.hopper()``)."""

    actor_hidden: tuple[int, ...] = widths((400, 300))
    """Hidden layer widths of the actor MLP (ReLU)."""
    critic_hidden: tuple[int, ...] = widths((400, 300))
    """Hidden layer widths of each of the twin critics (ReLU)."""
    batch_size: int = batch(100)
    """Replay transitions, and expert transitions, per update."""
    gamma: float = fraction(0.99)
    """Discount factor."""
    tau: float = fraction(0.005)
    """Polyak rate of the critics' targets."""
    lr: float = learning_rate(3e-4)
    """Adam learning rate of the actor and the critics."""
    exploration_noise: float = non_negative(0.1)
    """Std of the Gaussian noise added to actions when acting, in units of max_action."""
    policy_delay: int = count(2)
    """One actor and target update every policy_delay critic updates."""
    alpha: float = non_negative(0.1)
    """Weight of the DICE term: J0 = 2 alpha (1 - gamma) E[min_i Q_i(s, pi(s))]."""
    pi_reg_coef: float = non_negative(0.1)
    """Weight of the inverse-dynamics regulariser E[(IDM(s_E, s_E') - pi(s_E))^2] of the
    actor loss; 0 turns it off (the authors' "OPOLO-x")."""
    init_scheme: InitName = "glorot"
    """Initialisation of actor and critics (TensorFlow's default, the authors')."""
    idm_hidden: tuple[int, ...] = widths((256, 256))
    """Hidden layer widths of the inverse dynamics model (tanh)."""
    idm_lr: float = learning_rate(3e-4)
    """Adam learning rate of the inverse dynamics model."""
    idm_l2: float = non_negative(1e-3)
    """L2 weight of the inverse dynamics model's parameters."""
    idm_pretrain_steps: int = count(2500, low=0)
    """Gradient steps of the inverse dynamics model before the first update."""
    idm_every: int = count(500)
    """The inverse dynamics model takes ``idm_steps`` steps every this many updates."""
    idm_steps: int = count(50, low=0)
    """See ``idm_every``."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)

    @classmethod
    def hopper(cls, **overrides: Any) -> OPOLOConfig:
        """The authors' Hopper settings (opolo.yml): lr 1e-4, alpha 0.01, pi_reg_coef 0.01."""
        return cls(**{"lr": 1e-4, "alpha": 0.01, "pi_reg_coef": 0.01, **overrides})


class OPOLOState(flax.struct.PyTreeNode):
    """Everything OPOLO learns (a pytree): actor, critics and targets, the inverse dynamics
    model, the reward's (discriminator's) state, the normaliser, counters and a key."""

    actor_params: Params
    critic_params: Params
    critic_target: Params
    actor_opt_state: optax.OptState
    critic_opt_state: optax.OptState
    idm: InverseDynamicsState
    reward: Any
    obs_mean: jax.Array
    obs_std: jax.Array
    normalizer_set: jax.Array
    step: jax.Array
    """() int32, updates done."""
    idm_pretrained: jax.Array
    """() bool, whether the inverse dynamics model had its pretraining steps."""
    key: jax.Array


class OPOLO(NamedTuple):
    """OPOLO's functions (the loop's ``AgentFunctions``, and the reward of transitions)."""

    config: OPOLOConfig
    obs_dim: int
    action_dim: int
    max_action: float
    init: Callable[[int], OPOLOState]
    act: Callable[..., jax.Array]
    update: Callable[..., tuple[OPOLOState, dict[str, jax.Array]]]
    set_normalizer: Callable[[OPOLOState, ArrayLike, ArrayLike], OPOLOState]
    q_values: Callable[[OPOLOState, jax.Array, jax.Array], jax.Array]
    rewards: Callable[[OPOLOState, jax.Array, jax.Array], jax.Array]


class _Parts(NamedTuple):
    actor: DeterministicActor
    critic: CriticEnsemble
    opt: optax.GradientTransformation
    idm: InverseDynamics


def _normalize(state: OPOLOState | Policy, obs: jax.Array) -> jax.Array:
    return (obs - state.obs_mean) / state.obs_std


def _update_step(
    parts: _Parts,
    cfg: OPOLOConfig,
    setup: Any,
    expert_agent_obs: jax.Array,
    expert: Any,
    state: OPOLOState,
    batch: ReplayData,
    key: jax.Array,
    train_actor: bool | None = None,
):
    """One OPOLO update on a replay batch (see the module docstring); expert transitions are
    drawn here, ``batch_size`` of them."""
    tf = setup.time_feature
    idx = jax.random.randint(key, (cfg.batch_size,), 0, expert.obs.shape[0])
    reward = setup.reward.reward(
        state.reward, env_observations(batch.obs, tf), env_observations(batch.next_obs, tf)
    )
    obs_n, next_obs_n = _normalize(state, batch.obs), _normalize(state, batch.next_obs)
    next_q = jnp.min(
        parts.critic.apply(
            state.critic_target, next_obs_n, parts.actor.apply(state.actor_params, next_obs_n)
        ),
        axis=0,
    )
    target = jax.lax.stop_gradient(reward + cfg.gamma * batch.not_done * next_q)
    dice = 2.0 * cfg.alpha * (1.0 - cfg.gamma)
    pi_action = jax.lax.stop_gradient(parts.actor.apply(state.actor_params, obs_n))

    def critic_loss_fn(params: Params) -> tuple[jax.Array, jax.Array]:
        q = parts.critic.apply(params, obs_n, batch.action)  # (2, B)
        j0 = dice * jnp.mean(jnp.min(parts.critic.apply(params, obs_n, pi_action), axis=0))
        return j0 + 0.5 * jnp.sum(jnp.mean((target - q) ** 2, axis=-1)), jnp.mean(q)

    (c_loss, q_mean), grads = jax.value_and_grad(critic_loss_fn, has_aux=True)(state.critic_params)
    updates, critic_opt_state = parts.opt.update(grads, state.critic_opt_state)
    critic_params = optax.apply_updates(state.critic_params, updates)

    def actor_step(_: None):
        a_hat = jax.lax.stop_gradient(
            parts.idm.predict(state.idm, expert.obs[idx], expert.next_obs[idx])
        )
        expert_obs_n = _normalize(state, expert_agent_obs[idx])

        def actor_loss_fn(params: Params) -> jax.Array:
            q = parts.critic.apply(state.critic_params, obs_n, parts.actor.apply(params, obs_n))
            bc = jnp.mean((a_hat - parts.actor.apply(params, expert_obs_n)) ** 2)
            return -dice * jnp.mean(jnp.min(q, axis=0)) + cfg.pi_reg_coef * bc

        a_loss, a_grads = jax.value_and_grad(actor_loss_fn)(state.actor_params)
        a_updates, actor_opt_state = parts.opt.update(a_grads, state.actor_opt_state)
        actor_params = optax.apply_updates(state.actor_params, a_updates)
        critic_target = optax.incremental_update(critic_params, state.critic_target, cfg.tau)
        return actor_params, actor_opt_state, critic_target, a_loss

    def skip(_: None):
        zero = jnp.zeros((), jnp.float32)
        return state.actor_params, state.actor_opt_state, state.critic_target, zero

    do_actor, outs = delayed(train_actor, state.step, cfg.policy_delay, actor_step, skip)
    actor_params, actor_opt_state, critic_target, a_loss = outs
    new_state = state.replace(
        actor_params=actor_params,
        critic_params=critic_params,
        critic_target=critic_target,
        actor_opt_state=actor_opt_state,
        critic_opt_state=critic_opt_state,
        step=state.step + 1,
    )
    return new_state, (c_loss, a_loss, q_mean, do_actor, jnp.mean(reward))


def _idm_steps(
    parts: _Parts, cfg: OPOLOConfig, time_feature: bool, state: OPOLOState, data: ReplayData,
    size: jax.Array | int, num_steps: int,
) -> tuple[OPOLOState, dict[str, jax.Array]]:  # fmt: skip
    """``num_steps`` steps of the inverse dynamics model on uniform replay batches."""

    def body(idm_state: InverseDynamicsState, key: jax.Array):
        batch = sample_batch(data, size, key, cfg.batch_size)
        obs, next_obs = (
            env_observations(batch.obs, time_feature),
            env_observations(batch.next_obs, time_feature),
        )
        return parts.idm.update(idm_state, obs, batch.action, next_obs)

    key, k_steps = jax.random.split(state.key)
    idm_state, mse = jax.lax.scan(body, state.idm, jax.random.split(k_steps, num_steps))
    return state.replace(idm=idm_state, key=key), {"idm_loss": jnp.mean(mse)}


def _init_state(parts: _Parts, setup: Any, obs_dim: int, action_dim: int, seed: int) -> OPOLOState:
    key, k_actor, k_critic, k_idm, k_reward = jax.random.split(jax.random.PRNGKey(seed), 5)
    actor_params = parts.actor.init(k_actor, jnp.zeros((1, obs_dim), jnp.float32))
    critic_params = parts.critic.init(
        k_critic, jnp.zeros((1, obs_dim), jnp.float32), jnp.zeros((1, action_dim), jnp.float32)
    )
    return OPOLOState(
        actor_params=actor_params,
        critic_params=critic_params,
        critic_target=critic_params,
        actor_opt_state=parts.opt.init(actor_params),
        critic_opt_state=parts.opt.init(critic_params),
        idm=parts.idm.init(k_idm),
        reward=setup.reward.init(k_reward, setup.expert),
        obs_mean=jnp.zeros(obs_dim, jnp.float32),
        obs_std=jnp.ones(obs_dim, jnp.float32),
        normalizer_set=jnp.array(False),
        step=jnp.array(0, jnp.int32),
        idm_pretrained=jnp.array(False),
        key=key,
    )


def _agent_updates(
    parts: _Parts, cfg: OPOLOConfig, setup: Any, state: OPOLOState, data: ReplayData, size: Any,
    expert: Any, expert_agent_obs: jax.Array, num_updates: int,
) -> tuple[OPOLOState, dict[str, jax.Array]]:  # fmt: skip
    """``num_updates`` OPOLO updates in one ``lax.scan`` (the actor every ``policy_delay``)."""
    step = functools.partial(_update_step, parts, cfg, setup, expert_agent_obs, expert)
    state, outs = delayed_updates(
        step, cfg.policy_delay, state.step, state, data, size, num_updates, cfg.batch_size
    )
    c_loss, a_loss, q_mean, did_actor, reward = outs
    n_actor = jnp.maximum(jnp.sum(did_actor), 1)
    return state, {
        "critic_loss": jnp.mean(c_loss),
        "actor_loss": jnp.sum(jnp.where(did_actor, a_loss, 0.0)) / n_actor,
        "q_mean": jnp.mean(q_mean),
        "reward_mean": jnp.mean(reward),
    }


def make_opolo(
    config: OPOLOConfig, obs_dim: int, action_dim: int, max_action: float | ArrayLike, setup: Any
) -> OPOLO:
    """Build OPOLO's functions.

    Args:
        config: hyperparameters.
        obs_dim: the agent's observation size (time feature included where the run has one).
        action_dim: the action box is [-max_action, max_action]^action_dim.
        max_action: the bound, positive and the same in every dimension.
        setup: the learned reward and expert data (``ilfo.composition.learned.LearnedRewardSetup``);
            the reward is OPOLO's discriminator.
    """
    cfg, tf = config, setup.time_feature
    max_action = as_float_bound(max_action)
    env_dim = obs_dim - int(tf)
    parts = _Parts(
        actor=DeterministicActor(cfg.actor_hidden, action_dim, max_action, cfg.init_scheme),
        critic=CriticEnsemble(cfg.critic_hidden, 2, cfg.init_scheme),
        opt=optax.adam(cfg.lr),
        idm=InverseDynamics(
            InverseDynamicsConfig(cfg.idm_hidden, lr=cfg.idm_lr, l2=cfg.idm_l2), env_dim, action_dim
        ),
    )

    @jax.jit
    def act(state: OPOLOState | Policy, obs: jax.Array, key: jax.Array | None = None) -> jax.Array:
        action = parts.actor.apply(state.actor_params, _normalize(state, obs))
        if key is None:
            return action
        noise = jax.random.normal(key, action.shape) * (cfg.exploration_noise * max_action)
        return jnp.clip(action + noise, -max_action, max_action)

    agent_updates_jit = jax.jit(
        functools.partial(_agent_updates, parts, cfg, setup), static_argnames="num_updates"
    )
    idm_steps_jit = jax.jit(
        functools.partial(_idm_steps, parts, cfg, tf), static_argnames="num_steps"
    )
    idm_schedule = RewardSchedule(cfg.idm_every, cfg.idm_steps)
    reward_steps_jit = jax.jit(
        functools.partial(reward_steps, setup.reward, tf), static_argnames="num_steps"
    )

    def update(state: OPOLOState, data: ReplayData, size, num_updates: int):
        """The discriminator's and the model's steps that are due, then ``num_updates``
        OPOLO updates (see the module docstring)."""
        metrics: dict[str, jax.Array] = {}
        done = int(state.step)
        if not bool(state.idm_pretrained) and cfg.idm_pretrain_steps:
            state, _ = idm_steps_jit(state, data, size, num_steps=cfg.idm_pretrain_steps)
        state = state.replace(idm_pretrained=jnp.array(True))
        due = setup.schedule.steps_due(done, num_updates)
        if due:
            state, reward_metrics = reward_steps_jit(state, data, size, setup.expert, num_steps=due)
            metrics.update(reward_metrics)
        idm_due = idm_schedule.steps_due(done, num_updates)
        if idm_due:
            state, idm_metrics = idm_steps_jit(state, data, size, num_steps=idm_due)
            metrics.update(idm_metrics)
        state, agent_metrics = agent_updates_jit(
            state, data, size, setup.expert, setup.expert_agent_obs, num_updates=num_updates
        )
        return state, {**agent_metrics, **metrics}

    @jax.jit
    def q_values(state: OPOLOState, obs: jax.Array, action: jax.Array) -> jax.Array:
        return parts.critic.apply(state.critic_params, _normalize(state, obs), action)

    return OPOLO(
        config=cfg,
        obs_dim=obs_dim,
        action_dim=action_dim,
        max_action=max_action,
        init=functools.partial(_init_state, parts, setup, obs_dim, action_dim),
        act=act,
        update=update,
        set_normalizer=make_normalizer_setter(obs_dim, tf),
        q_values=q_values,
        rewards=jax.jit(lambda s, obs, next_obs: setup.reward.reward(s.reward, obs, next_obs)),
    )
