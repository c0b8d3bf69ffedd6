"""f-IRL, forward-KL variant (Ni, Sikchi, Wang, Gupta, Lee, Eysenbach, CoRL 2020): a state-only
reward network learned by matching state marginals.

Follows the authors' code (twni2016/f-IRL: ``firl/irl_samples.py``, ``firl/divs/f_div_disc.py``,
``firl/models/reward.py``, ``firl/models/discrim.py`` and the MuJoCo configs with ``obj: fkl``;
docs/reproduction.md has the table of where ilfo departs). Each outer iteration, after
``iteration_steps`` environment steps of the agent (SAC) on the current reward:

1. ``rollouts`` fresh fixed-horizon episodes of the current stochastic policy (their states
   s_1..s_T) - collected by the training loop, not drawn from the replay buffer;
2. a discriminator D (a residual tanh MLP, logit clipped to +-10) trained ``disc_steps`` steps to
   tell expert states (label 1) from those agent states (label 0), warm-started across
   iterations; its logit estimates log rho_E(s) / rho_theta(s);
3. one Adam step of the reward network r_theta(s) on the FKL surrogate
   L = (1 / T) Cov_i(a_i, b_i), the biased covariance over trajectories i of
   a_i = -sum_t exp(logit(s_it)) (fixed) and b_i = sum_t r_theta(s_it), over the agent's
   rollouts and ``expert_resample`` expert trajectories drawn afresh (the code's estimator; 0
   keeps to the agent's trajectories, the theorem's). Its gradient is alpha times the paper's
   Theorem 4.1 gradient of FKL(rho_E || rho_theta) (the code drops the 1 / alpha).

The agent's batches are rewarded by r_theta(s) of the state before the action (the code's
``batch['obs']``), with the current parameters (``ilfo.composition.learned``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import flax
import flax.linen as nn
import jax
import jax.numpy as jnp
import optax

from ilfo.networks import ArrayModule, dense
from ilfo.ranges import (
    batch,
    check_fields,
    count,
    learning_rate,
    non_negative,
    positive,
    width,
    widths,
)
from ilfo.rewards.learned import Transitions

__all__ = ["FIRL", "FIRLConfig", "FIRLState", "fkl_surrogate"]


@dataclasses.dataclass(frozen=True)
class FIRLConfig:
    """f-IRL (FKL). Defaults: the authors' MuJoCo configs (Hopper, Walker2d, HalfCheetah; Ant
    uses ``reward_hidden=(128, 128)``, ``disc_blocks=6``)."""

    reward_hidden: tuple[int, ...] = widths((64, 64), min_items=1)
    """Widths of the reward network: Linear(d, h0), then Linear(h_i, h_i+1) + ReLU for each next
    width, then Linear(., 1) (the code's layout: no activation after the first layer)."""
    reward_lr: float = learning_rate(1e-4)
    """Adam learning rate of the reward network."""
    reward_weight_decay: float = non_negative(1e-3)
    """L2 weight added to the reward network's gradient (PyTorch Adam's coupled weight decay)."""
    reward_clip: float = positive(10.0)
    """The reward is clipped to [-reward_clip, reward_clip]."""
    disc_hidden: int = width(128)
    """Width of the discriminator."""
    disc_blocks: int = count(3)
    """Discriminator layout: Linear(d, w), then disc_blocks - 1 residual blocks
    x + tanh(Linear(w, w) x), then Linear(w, 1)."""
    disc_lr: float = learning_rate(3e-4)
    """Adam learning rate of the discriminator."""
    disc_weight_decay: float = non_negative(1e-4)
    """Coupled L2 weight of the discriminator."""
    disc_batch_size: int = batch(800)
    """Expert states and agent states per discriminator step (each)."""
    disc_steps: int = count(1200, low=0)
    """Discriminator steps per outer iteration."""
    disc_clip: float = positive(10.0)
    """The discriminator's logit is clipped to [-disc_clip, disc_clip]."""
    rollouts: int = count(10)
    """Fresh episodes of the current policy per outer iteration."""
    expert_resample: int = count(10, low=0)
    """Expert trajectories drawn into the covariance each iteration (with replacement when more
    than the demos); 0: the agent's rollouts alone (the theorem's estimator)."""
    iteration_steps: int = count(5000)
    """Environment steps of the agent between reward updates (the code's 5 x 1000)."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


class RewardNet(ArrayModule):
    """r_theta(s) in the code's layout (see ``FIRLConfig.reward_hidden``), PyTorch init."""

    hidden: tuple[int, ...]
    clip: float

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        x = dense(self.hidden[0], x.shape[-1], "torch")(x)
        for features in self.hidden[1:]:
            x = nn.relu(dense(features, x.shape[-1], "torch")(x))
        return jnp.clip(dense(1, x.shape[-1], "torch")(x)[..., 0], -self.clip, self.clip)


class DensityRatioNet(ArrayModule):
    """The discriminator's logit, ~log rho_E(s) / rho_theta(s) (see ``FIRLConfig.disc_blocks``)."""

    width: int
    blocks: int
    clip: float

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        x = dense(self.width, x.shape[-1], "torch")(x)
        for _ in range(self.blocks - 1):
            x = x + nn.tanh(dense(self.width, self.width, "torch")(x))
        return jnp.clip(dense(1, self.width, "torch")(x)[..., 0], -self.clip, self.clip)


def fkl_surrogate(log_ratio: jax.Array, rewards: jax.Array) -> jax.Array:
    """The code's FKL reward loss of trajectories (N, T): (1 / T) [mean_i a_i b_i - mean_i a_i
    mean_i b_i] with a_i = -sum_t exp(log_ratio_it) (no gradient) and b_i = sum_t rewards_it.

    Minimised, it raises the reward of trajectories whose states the expert visits more than
    the agent; with agent trajectories only, its gradient is alpha times that of
    FKL(rho_E || rho_theta) for a max-ent agent at temperature alpha (Ni et al., Thm 4.1)."""
    a = -jnp.sum(jnp.exp(jax.lax.stop_gradient(log_ratio)), axis=-1)
    b = jnp.sum(rewards, axis=-1)
    return (jnp.mean(a * b) - jnp.mean(a) * jnp.mean(b)) / rewards.shape[-1]


class FIRLState(flax.struct.PyTreeNode):
    """The reward network and the discriminator, with their optimiser states (a pytree)."""

    reward_params: Any
    reward_opt_state: optax.OptState
    disc_params: Any
    disc_opt_state: optax.OptState


def _adam_l2(lr: float, weight_decay: float) -> optax.GradientTransformation:
    # PyTorch's Adam(weight_decay=w): w * theta is added to the gradient before Adam.
    return optax.chain(optax.add_decayed_weights(weight_decay), optax.adam(lr))


class FIRL:
    """f-IRL's learned reward r_theta(s) (pure functions; the config closed over)."""

    def __init__(self, config: FIRLConfig) -> None:
        self.config = config
        self.batch_size = config.disc_batch_size
        self._reward = RewardNet(config.reward_hidden, config.reward_clip)
        self._disc = DensityRatioNet(config.disc_hidden, config.disc_blocks, config.disc_clip)
        self._reward_opt = _adam_l2(config.reward_lr, config.reward_weight_decay)
        self._disc_opt = _adam_l2(config.disc_lr, config.disc_weight_decay)

    def init(self, key: jax.Array, expert: Transitions) -> FIRLState:
        """Fresh networks (``expert`` gives the input size)."""
        k_reward, k_disc = jax.random.split(key)
        x = jnp.zeros((1, expert.obs.shape[-1]), jnp.float32)
        reward_params = self._reward.init(k_reward, x)
        disc_params = self._disc.init(k_disc, x)
        return FIRLState(
            reward_params,
            self._reward_opt.init(reward_params),
            disc_params,
            self._disc_opt.init(disc_params),
        )

    def reward(self, state: FIRLState, obs: jax.Array, next_obs: jax.Array) -> jax.Array:
        """r_theta(s) of the state before each transition (the code's)."""
        return self._reward.apply(state.reward_params, obs)

    def log_ratio(self, state: FIRLState, states: jax.Array) -> jax.Array:
        """The discriminator's clipped logit, ~log rho_E(s) / rho_theta(s)."""
        return self._disc.apply(state.disc_params, states)

    def _disc_step(self, state: FIRLState, agent: jax.Array, expert: jax.Array, key: jax.Array):
        k_agent, k_expert = jax.random.split(key)
        n = self.config.disc_batch_size
        x_a = agent[jax.random.randint(k_agent, (n,), 0, agent.shape[0])]
        x_e = expert[jax.random.randint(k_expert, (n,), 0, expert.shape[0])]

        def loss_fn(params: Any) -> tuple[jax.Array, jax.Array]:
            l_e, l_a = self._disc.apply(params, x_e), self._disc.apply(params, x_a)
            bce = 0.5 * (jnp.mean(jax.nn.softplus(-l_e)) + jnp.mean(jax.nn.softplus(l_a)))
            return bce, 0.5 * (jnp.mean(l_e > 0) + jnp.mean(l_a < 0))

        (loss, accuracy), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.disc_params)
        updates, opt_state = self._disc_opt.update(grads, state.disc_opt_state, state.disc_params)
        params = optax.apply_updates(state.disc_params, updates)
        return state.replace(disc_params=params, disc_opt_state=opt_state), (loss, accuracy)

    def update_from_rollouts(
        self, state: FIRLState, agent_trajs: jax.Array, expert_trajs: jax.Array, key: jax.Array
    ) -> tuple[FIRLState, dict[str, jax.Array]]:
        """One outer iteration's learning (steps 2 and 3 of the module docstring) from the
        agent's fresh trajectories (n, T, d) and the expert's (E, T, d)."""
        cfg = self.config
        k_disc, k_resample = jax.random.split(key)
        agent_states = agent_trajs.reshape(-1, agent_trajs.shape[-1])
        expert_states = expert_trajs.reshape(-1, expert_trajs.shape[-1])

        def disc_body(s: FIRLState, k: jax.Array):
            return self._disc_step(s, agent_states, expert_states, k)

        state, (disc_loss, disc_acc) = jax.lax.scan(
            disc_body, state, jax.random.split(k_disc, cfg.disc_steps)
        )
        trajs = agent_trajs
        if cfg.expert_resample:
            num_expert = expert_trajs.shape[0]
            idx = jax.random.choice(
                k_resample,
                num_expert,
                (cfg.expert_resample,),
                replace=cfg.expert_resample > num_expert,
            )
            trajs = jnp.concatenate([agent_trajs, expert_trajs[idx]])
        log_ratio = self.log_ratio(state, trajs)

        def reward_loss(params: Any) -> jax.Array:
            return fkl_surrogate(log_ratio, self._reward.apply(params, trajs))

        loss, grads = jax.value_and_grad(reward_loss)(state.reward_params)
        updates, opt_state = self._reward_opt.update(
            grads, state.reward_opt_state, state.reward_params
        )
        params = optax.apply_updates(state.reward_params, updates)
        state = state.replace(reward_params=params, reward_opt_state=opt_state)
        metrics = {
            "reward_loss": loss,
            "disc_loss": jnp.mean(disc_loss[-10:]) if cfg.disc_steps else jnp.nan,
            "reward_accuracy": jnp.mean(disc_acc[-10:]) if cfg.disc_steps else jnp.nan,
        }
        return state, metrics
