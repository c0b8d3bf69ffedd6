"""TRPO (Schulman et al. 2015) as the Sinkhorn Imitation Learning authors configured it.

On-policy: ``learn`` takes one whole batch of the current policy's episodes and does ONE TRPO
iteration on it (docs/notes/sil-spec.md, sections 6 and 7: the SIL code's TRPO, Khrylx's
PyTorch-RL):

1. V_old: the value network on every batch state, before any update;
2. GAE (gamma, lambda), cut at every episode end (time limits included; nothing is bootstrapped
   past one); returns R = V_old + A; the advantages are then normalised over the batch (ddof 1);
3. the value fit: full-batch L-BFGS-B (scipy, ``value_iters`` iterations) on
   mean((V - R)^2) + value_l2 * |theta|^2, from the current parameters;
4. the policy step: the surrogate L = mean(-A * pi(a|s) / pi_old(a|s)), its gradient g,
   conjugate gradients on F x = -g (F: the Hessian of the mean KL(pi_old || pi) at the old
   parameters, which for this Gaussian is the analytic Fisher, plus ``damping``), the step
   scaled to 0.5 s^T F s = max_kl, and a backtracking line search over fractions 0.5^k that
   accepts the first step whose actual improvement is more than ``accept_ratio`` of the
   expected one. None accepted: the policy is unchanged.

The policy is a Gaussian N(mean(s), exp(log_std)^2): a (128, 128) ReLU MLP for the mean and one
state-independent log std per action dimension, not clamped; actions are neither squashed nor
clipped (the training loop clips what it sends to the environment). The networks see
clip((obs - obs_mean) / obs_std, -obs_clip, obs_clip).

Usage::

    agent = make_trpo(TRPOConfig(), obs_dim, action_dim, max_action)
    state = agent.init(seed=0)
    action = agent.act(state, obs, key)          # a sample; key=None: the mean
    state, metrics = agent.learn(state, OnPolicyBatch(obs, action, reward, episode_end))

Where ilfo departs from the SIL authors' TRPO:

- ``kl_check`` (default True): the line search also rejects a step whose mean KL(old || new)
  exceeds ``max_kl``, so every accepted step keeps to the trust region. The SIL code checks only
  the improvement ratio (``kl_check=False`` is the code's).
- ``code_fisher`` (default True) is not a departure but a quirk kept: the code's Fisher-vector
  product adds 2 v to every parameter, not only to the log std (``TRPOConfig.code_fisher``).
- float32 networks and JAX computations (the SIL code runs in float64); the L-BFGS-B of the
  value fit works in float64 on the host, on float32 losses and gradients.
- Degenerate batches are guarded where the code would produce NaN: advantages with zero spread
  are all 0 (no step); a step whose s^T F s or expected improvement is not positive and finite
  is rejected; conjugate gradients return 0 when |g|^2 is already below the tolerance (the code
  always takes one iteration and divides 0 by 0).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import flax
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize
from jax.flatten_util import ravel_pytree
from numpy.typing import ArrayLike

from ilfo.agents._common import Policy, as_float_bound, make_normalizer_setter
from ilfo.agents.base import OnPolicyBatch
from ilfo.agents.trust_region import (
    LOG_2PI,
    conjugate_gradients,
    fisher_vector_product,
    gae,
    gaussian_kl,
    gaussian_log_prob,
)
from ilfo.networks import ArrayModule, PairModule, dense
from ilfo.ranges import between, check_fields, count, fraction, non_negative, positive, widths

__all__ = [
    "TRPO",
    "GaussianMLPPolicy",
    "OnPolicyBatch",
    "TRPOConfig",
    "TRPOState",
    "ValueMLP",
    "conjugate_gradients",
    "fisher_vector_product",
    "gae",
    "gaussian_kl",
    "gaussian_log_prob",
    "make_trpo",
]

Params = Any


@dataclasses.dataclass(frozen=True)
class TRPOConfig:
    """Hyperparameters of TRPO. Defaults: the SIL authors' code (docs/notes/sil-spec.md, section
    6), except ``kl_check``."""

    hidden: tuple[int, ...] = widths((128, 128), min_items=1)
    """Hidden layer widths of the policy-mean MLP and of the value MLP (ReLU, as SIL's code)."""
    log_std_init: float = 0.0
    """Initial log std of the policy, one state-independent parameter per action dimension (not
    clamped while learning)."""
    max_kl: float = positive(0.1)
    """Trust region: the step is scaled so that its quadratic model of the mean KL(old || new)
    is max_kl. SIL's code uses 0.1 (10x the usual 0.01)."""
    damping: float = non_negative(0.1)
    """Added to the Fisher: the conjugate gradients solve (F + damping I) x = -g."""
    cg_iters: int = count(10)
    """Conjugate gradient iterations (fewer if the residual r.r falls below 1e-10)."""
    line_search_steps: int = count(10)
    """Backtracking line search: step fractions 0.5^k for k = 0 .. line_search_steps - 1."""
    accept_ratio: float = positive(0.1)
    """A line-search step is accepted when its actual surrogate improvement exceeds this
    fraction of the expected (linear) one."""
    code_fisher: bool = True
    """The authors' Fisher-vector product: the KL's Hessian plus 2 v on the mean network's
    parameters too (Khrylx's code adds 2 v to a slice meant for the log std, but the slice
    starts at 0, the log std being the module's first parameter, and spans N x action_dim
    entries: every parameter). Its steps are several times shorter than the exact Hessian's
    (the mean network's Fisher has mostly tiny eigenvalues). False: the exact Hessian of the
    mean KL (2 v on the log std only)."""
    kl_check: bool = True
    """Also reject a line-search step whose mean KL(old || new) exceeds max_kl, so that every
    accepted step keeps to the trust region. SIL's code has no such check (False = the code's);
    ilfo departs from it here."""
    gamma: float = fraction(0.99)
    """Discount factor."""
    gae_lambda: float = between(0.97, 0.0, 1.0)
    """GAE lambda (SIL's README runs 0.97; its script's default is 0.99)."""
    value_l2: float = non_negative(1e-3)
    """L2 penalty on all value network parameters, biases included, in the value fit."""
    value_iters: int = count(25)
    """L-BFGS-B iterations of the full-batch value fit, per learn."""
    batch_steps: int = count(50_000)
    """An iteration learns once at least this many steps (whole episodes) are collected."""
    obs_clip: float = positive(5.0)
    """The normalised observation is clipped to +-obs_clip (SIL's ZFilter)."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


class TRPOState(flax.struct.PyTreeNode):
    """Everything TRPO learns (a pytree). No optimiser state: each iteration starts afresh."""

    actor_params: Params
    """The policy: the mean MLP's parameters and the log std, one pytree (what a ``Policy``
    holds)."""
    value_params: Params
    """The value network's parameters."""
    obs_mean: jax.Array
    """(obs_dim,) networks see clip((obs - obs_mean) / obs_std, -obs_clip, obs_clip)."""
    obs_std: jax.Array
    """(obs_dim,)"""
    normalizer_set: jax.Array
    """() bool, True once ``set_normalizer`` has been called."""
    iterations: jax.Array
    """() int32, TRPO iterations (``learn`` calls) done, whether or not the step was accepted."""


class TRPO(NamedTuple):
    """The functions of a TRPO agent built by ``make_trpo`` (config closed over)."""

    config: TRPOConfig
    obs_dim: int
    action_dim: int
    max_action: float
    """Bound of the environment's action box; the loop clips to it, ``act`` does not."""
    batch_steps: int
    """Collect at least this many steps (whole episodes) per ``learn``."""
    init: Callable[[int], TRPOState]
    """init(seed) -> state with fresh parameters and an identity normaliser."""
    act: Callable[..., jax.Array]
    """act(state or Policy, obs (..., obs_dim), key=None) -> action (..., action_dim). key None:
    the mean (evaluation); else a sample of N(mean, exp(log_std)^2). Not squashed, not
    clipped."""
    set_normalizer: Callable[[TRPOState, ArrayLike, ArrayLike], TRPOState]
    """set_normalizer(state, mean (obs_dim,), std (obs_dim,)) -> state; allowed once."""
    learn: Callable[[TRPOState, OnPolicyBatch], tuple[TRPOState, dict[str, float]]]
    """learn(state, batch) -> (state, metrics): one TRPO iteration on the whole batch. Metrics
    (floats): value_loss (mean squared error after the fit), surrogate_improvement, kl and
    step_fraction (of the accepted step; 0 when none was), entropy and mean_std (of the policy
    after the step)."""
    log_prob: Callable[[TRPOState | Policy, jax.Array, jax.Array], jax.Array]
    """log_prob(state or Policy, obs (..., obs_dim), action (..., action_dim)) -> (...): the
    Gaussian log density summed over action dimensions."""
    value: Callable[[TRPOState, jax.Array], jax.Array]
    """value(state, obs (..., obs_dim)) -> (...): the value network (for diagnostics)."""


class _SmallHeadMLP(ArrayModule):
    """ReLU MLP in PyTorch's default initialisation, whose linear output layer starts 10x
    smaller (weights uniform +-0.1/sqrt(fan_in)) with zero biases, as SIL's policy and value
    heads (PyTorch's init, then weight * 0.1 and bias 0)."""

    hidden: Sequence[int]
    out_dim: int

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for width in self.hidden:
            x = nn.relu(dense(width, x.shape[-1], "torch")(x))
        # variance_scaling(s, fan_in, uniform) draws from +-sqrt(3 s / fan_in) = +-0.1/sqrt(fan_in).
        kernel_init = nn.initializers.variance_scaling(0.01 / 3.0, "fan_in", "uniform")
        return nn.Dense(self.out_dim, kernel_init=kernel_init, bias_init=nn.initializers.zeros)(x)


class GaussianMLPPolicy(PairModule):
    """obs (..., obs_dim) -> (mean, log_std), each (..., action_dim); log_std is one
    state-independent parameter per action dimension (broadcast), not clamped."""

    hidden: Sequence[int]
    action_dim: int
    log_std_init: float = 0.0

    @nn.compact
    def __call__(self, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        mean = _SmallHeadMLP(self.hidden, self.action_dim, name="mean")(obs)
        log_std = self.param(
            "log_std", nn.initializers.constant(self.log_std_init), (self.action_dim,)
        )
        return mean, jnp.broadcast_to(log_std, mean.shape)


class ValueMLP(ArrayModule):
    """obs (..., obs_dim) -> V (...)."""

    hidden: Sequence[int]

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return _SmallHeadMLP(self.hidden, 1, name="value")(obs)[..., 0]


def _check_batch(batch: OnPolicyBatch, obs_dim: int, action_dim: int) -> tuple[np.ndarray, ...]:
    """The batch as numpy (float32 obs and actions, float64 rewards, bool ends), or a
    ValueError saying what is wrong with it."""
    obs = np.asarray(batch.obs)
    action = np.asarray(batch.action)
    reward = np.asarray(batch.reward)
    end = np.asarray(batch.episode_end)
    n = obs.shape[0] if obs.ndim == 2 else -1
    if obs.shape != (n, obs_dim):
        raise ValueError(f"batch.obs must have shape (N, {obs_dim}), got {obs.shape}")
    if action.shape != (n, action_dim):
        raise ValueError(f"batch.action must have shape ({n}, {action_dim}), got {action.shape}")
    if reward.shape != (n,) or end.shape != (n,):
        raise ValueError(
            f"batch.reward and batch.episode_end must have shape ({n},), got {reward.shape} "
            f"and {end.shape}"
        )
    if n < 2:
        raise ValueError(f"a TRPO batch needs at least 2 steps, got {n}")
    for name, array in (("obs", obs), ("action", action), ("reward", reward)):
        if not np.issubdtype(array.dtype, np.number) or not np.all(np.isfinite(array)):
            raise ValueError(f"batch.{name} must be finite numbers")
    if end.dtype != bool:
        if not np.all((end == 0) | (end == 1)):
            raise ValueError("batch.episode_end must be booleans")
        end = end.astype(bool)
    if not end[-1]:
        raise ValueError("the batch must end on an episode end (batch.episode_end[-1] False)")
    return obs.astype(np.float32), action.astype(np.float32), reward.astype(np.float64), end


class _Networks(NamedTuple):
    """TRPO's networks and the flat views of their parameters that the host side works on."""

    policy: GaussianMLPPolicy
    value: ValueMLP
    actor_from_flat: Callable[[jax.Array], Params]
    value_from_flat: Callable[[jax.Array], Params]
    template: jax.Array
    """(1, obs_dim) zeros: what ``init`` traces the networks with."""


def _networks(cfg: TRPOConfig, obs_dim: int, action_dim: int) -> _Networks:
    policy = GaussianMLPPolicy(cfg.hidden, action_dim, cfg.log_std_init)
    value = ValueMLP(cfg.hidden)
    # Only the structure of these parameters is used (eval_shape: nothing is computed).
    template = jnp.zeros((1, obs_dim), jnp.float32)
    shapes = [jax.eval_shape(net.init, jax.random.PRNGKey(0), template) for net in (policy, value)]
    actor_from_flat, value_from_flat = (
        ravel_pytree(jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), s))[1] for s in shapes
    )
    return _Networks(policy, value, actor_from_flat, value_from_flat, template)


def _init(nets: _Networks, obs_dim: int, seed: int) -> TRPOState:
    k_policy, k_value = jax.random.split(jax.random.PRNGKey(seed))
    return TRPOState(
        actor_params=nets.policy.init(k_policy, nets.template),
        value_params=nets.value.init(k_value, nets.template),
        obs_mean=jnp.zeros(obs_dim, jnp.float32),
        obs_std=jnp.ones(obs_dim, jnp.float32),
        normalizer_set=jnp.array(False),
        iterations=jnp.array(0, jnp.int32),
    )


def _normalize(cfg: TRPOConfig, state: TRPOState | Policy, obs: jax.Array) -> jax.Array:
    obs_n = (obs - state.obs_mean) / state.obs_std
    return jnp.clip(obs_n, -cfg.obs_clip, cfg.obs_clip)


def _act(
    nets: _Networks,
    cfg: TRPOConfig,
    state: TRPOState | Policy,
    obs: jax.Array,
    key: jax.Array | None = None,
) -> jax.Array:
    mean, log_std = nets.policy.apply(state.actor_params, _normalize(cfg, state, obs))
    if key is None:
        return mean
    return mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape, mean.dtype)


def _log_prob(
    nets: _Networks, cfg: TRPOConfig, state: TRPOState | Policy, obs: jax.Array, action: jax.Array
) -> jax.Array:
    mean, log_std = nets.policy.apply(state.actor_params, _normalize(cfg, state, obs))
    return gaussian_log_prob(mean, log_std, action)


def _value_of(nets: _Networks, cfg: TRPOConfig, state: TRPOState, obs: jax.Array) -> jax.Array:
    return nets.value.apply(state.value_params, _normalize(cfg, state, obs))


def _normalized_values(
    nets: _Networks, cfg: TRPOConfig, state: TRPOState, obs: jax.Array
) -> tuple[jax.Array, jax.Array]:
    obs_n = _normalize(cfg, state, obs)
    return obs_n, nets.value.apply(state.value_params, obs_n)


def _value_objective(
    nets: _Networks, cfg: TRPOConfig, flat: jax.Array, obs_n: jax.Array, target: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """The value fit's loss and its gradient at the flat value parameters ``flat``."""

    def loss(f: jax.Array) -> jax.Array:
        v = nets.value.apply(nets.value_from_flat(f), obs_n)
        return jnp.mean((v - target) ** 2) + cfg.value_l2 * jnp.sum(f**2)

    return jax.value_and_grad(loss)(flat)


def _value_mse(nets: _Networks, flat: jax.Array, obs_n: jax.Array, target: jax.Array) -> jax.Array:
    return jnp.mean((nets.value.apply(nets.value_from_flat(flat), obs_n) - target) ** 2)


def _policy_direction(
    nets: _Networks,
    cfg: TRPOConfig,
    actor_params: Params,
    obs_n: jax.Array,
    action: jax.Array,
    adv: jax.Array,
) -> tuple[jax.Array, ...]:
    """The old policy's log densities and outputs, the surrogate's gradient g, the CG
    direction s ~ -(F + damping)^-1 g, and s^T (F + damping) s."""
    policy, actor_from_flat = nets.policy, nets.actor_from_flat
    mean_old, log_std_old = policy.apply(actor_params, obs_n)
    logp_old = gaussian_log_prob(mean_old, log_std_old, action)
    flat0 = ravel_pytree(actor_params)[0]

    def surrogate(flat: jax.Array) -> jax.Array:
        mean, log_std = policy.apply(actor_from_flat(flat), obs_n)
        ratio = jnp.exp(gaussian_log_prob(mean, log_std, action) - logp_old)
        return jnp.mean(-adv * ratio)

    grad = jax.grad(surrogate)(flat0)
    fvp = fisher_vector_product(policy, actor_params, obs_n, cfg.damping, cfg.code_fisher)

    def fvp_flat(v: jax.Array) -> jax.Array:
        return ravel_pytree(fvp(actor_from_flat(v)))[0]

    step = conjugate_gradients(fvp_flat, -grad, cfg.cg_iters)
    s_f_s = jnp.dot(step, fvp_flat(step))
    return grad, step, s_f_s, logp_old, mean_old, log_std_old


def _evaluate(
    nets: _Networks,
    flat: jax.Array,
    obs_n: jax.Array,
    action: jax.Array,
    adv: jax.Array,
    logp_old: jax.Array,
    mean_old: jax.Array,
    log_std_old: jax.Array,
) -> tuple[jax.Array, jax.Array]:
    """(surrogate, mean KL(old || new)) of the flat policy parameters ``flat``."""
    mean, log_std = nets.policy.apply(nets.actor_from_flat(flat), obs_n)
    ratio = jnp.exp(gaussian_log_prob(mean, log_std, action) - logp_old)
    kl = jnp.mean(gaussian_kl(mean_old, log_std_old, mean, log_std))
    return jnp.mean(-adv * ratio), kl


class _Jitted(NamedTuple):
    """The jitted pieces the host side of ``learn`` calls (eagerly, each small operation would
    compile on its own)."""

    ravel: Callable[[Params], jax.Array]
    unravel_actor: Callable[[jax.Array], Params]
    unravel_value: Callable[[jax.Array], Params]
    normalized_values: Callable[..., tuple[jax.Array, jax.Array]]
    value_objective: Callable[..., tuple[jax.Array, jax.Array]]
    value_mse: Callable[..., jax.Array]
    policy_direction: Callable[..., tuple[jax.Array, ...]]
    evaluate: Callable[..., tuple[jax.Array, jax.Array]]


def _jitted(nets: _Networks, cfg: TRPOConfig) -> _Jitted:
    return _Jitted(
        ravel=jax.jit(lambda params: ravel_pytree(params)[0]),
        unravel_actor=jax.jit(nets.actor_from_flat),
        unravel_value=jax.jit(nets.value_from_flat),
        normalized_values=jax.jit(functools.partial(_normalized_values, nets, cfg)),
        value_objective=jax.jit(functools.partial(_value_objective, nets, cfg)),
        value_mse=jax.jit(functools.partial(_value_mse, nets)),
        policy_direction=jax.jit(functools.partial(_policy_direction, nets, cfg)),
        evaluate=jax.jit(functools.partial(_evaluate, nets)),
    )


def _fit_value(
    fns: _Jitted, cfg: TRPOConfig, state: TRPOState, obs_n: jax.Array, target: jax.Array
) -> tuple[Params, float]:
    """Full-batch L-BFGS-B from the current parameters, as SIL's code (scipy's defaults
    otherwise); scipy works in float64 on float32 losses and gradients."""

    def objective(x: np.ndarray) -> tuple[float, np.ndarray]:
        loss, grad = fns.value_objective(jnp.asarray(x.astype(np.float32)), obs_n, target)
        return float(loss), np.asarray(grad, np.float64)

    x0 = np.asarray(fns.ravel(state.value_params), np.float64)
    result = scipy.optimize.minimize(
        objective, x0, jac=True, method="L-BFGS-B", options={"maxiter": cfg.value_iters}
    )
    flat = jnp.asarray(result.x.astype(np.float32))
    return fns.unravel_value(flat), float(fns.value_mse(flat, obs_n, target))


def _line_search(
    fns: _Jitted,
    cfg: TRPOConfig,
    state: TRPOState,
    obs_n: jax.Array,
    action: jax.Array,
    adv: jax.Array,
) -> tuple[Params, tuple[float, float, float]]:
    """The policy step: the new actor parameters and (fraction, surrogate improvement, KL)
    of the accepted step, or the old parameters and zeros when no step is accepted."""
    grad_dev, step_dev, s_f_s_dev, *old = fns.policy_direction(
        state.actor_params, obs_n, action, adv
    )
    grad, step, s_f_s = np.asarray(grad_dev), np.asarray(step_dev), float(s_f_s_dev)
    flat0 = np.asarray(fns.ravel(state.actor_params))
    surrogate_old = float(fns.evaluate(flat0, obs_n, action, adv, *old)[0])
    if not (math.isfinite(s_f_s) and s_f_s > 0):
        return state.actor_params, (0.0, 0.0, 0.0)
    # Scaled so that the quadratic model of the KL, 0.5 s^T F s, equals max_kl.
    full_step = step * np.float32(math.sqrt(cfg.max_kl / (0.5 * s_f_s)))
    expected_full = -float(np.dot(grad.astype(np.float64), full_step))
    if not (math.isfinite(expected_full) and expected_full > 0):
        return state.actor_params, (0.0, 0.0, 0.0)
    for k in range(cfg.line_search_steps):
        fraction = 0.5**k
        candidate = flat0 + np.float32(fraction) * full_step
        surrogate_new, kl = map(float, fns.evaluate(candidate, obs_n, action, adv, *old))
        improvement = surrogate_old - surrogate_new
        if improvement / (expected_full * fraction) > cfg.accept_ratio and (
            not cfg.kl_check or kl <= cfg.max_kl
        ):
            return fns.unravel_actor(jnp.asarray(candidate)), (fraction, improvement, kl)
    return state.actor_params, (0.0, 0.0, 0.0)


def _learn(
    fns: _Jitted,
    cfg: TRPOConfig,
    obs_dim: int,
    action_dim: int,
    state: TRPOState,
    batch: OnPolicyBatch,
) -> tuple[TRPOState, dict[str, float]]:
    """One TRPO iteration on ``batch`` (whole episodes of the current policy): value fit,
    then the policy step. Deterministic."""
    obs, action, reward, end = _check_batch(batch, obs_dim, action_dim)
    obs_n, v_old_dev = fns.normalized_values(state, jnp.asarray(obs))
    v_old = np.asarray(v_old_dev, np.float64)
    advantages = gae(reward, v_old, end, cfg.gamma, cfg.gae_lambda)
    target = jnp.asarray((v_old + advantages).astype(np.float32))
    spread = advantages.std(ddof=1)
    # All-equal advantages carry no direction: 0 (then no step) rather than 0/0.
    adv_n = (advantages - advantages.mean()) / (spread if spread > 0 else 1.0)

    value_params, value_loss = _fit_value(fns, cfg, state, obs_n, target)
    actor_params, (fraction, improvement, kl) = _line_search(
        fns, cfg, state, obs_n, jnp.asarray(action), jnp.asarray(adv_n.astype(np.float32))
    )

    new_state = state.replace(
        actor_params=actor_params,
        value_params=value_params,
        iterations=jnp.asarray(int(state.iterations) + 1, jnp.int32),
    )
    log_std = np.asarray(actor_params["params"]["log_std"], np.float64)
    metrics = {
        "value_loss": value_loss,
        "surrogate_improvement": improvement,
        "kl": kl,
        "step_fraction": fraction,
        "entropy": float(np.sum(log_std + 0.5 * (1.0 + LOG_2PI))),
        "mean_std": float(np.mean(np.exp(log_std))),
    }
    return new_state, metrics


def make_trpo(
    config: TRPOConfig, obs_dim: int, action_dim: int, max_action: float | ArrayLike = 1.0
) -> TRPO:
    """Build the functions of a TRPO agent.

    Args:
        config: hyperparameters.
        obs_dim: observation size.
        action_dim: action size.
        max_action: bound of the symmetric action box, the same for every dimension (recorded
            for the loop, which clips; the policy itself is unbounded).
    """
    cfg = config
    if obs_dim < 1 or action_dim < 1:
        raise ValueError(f"obs_dim and action_dim must be positive, got {obs_dim}, {action_dim}")
    nets = _networks(cfg, obs_dim, action_dim)
    return TRPO(
        config=cfg,
        obs_dim=obs_dim,
        action_dim=action_dim,
        max_action=as_float_bound(max_action),
        batch_steps=cfg.batch_steps,
        init=jax.jit(functools.partial(_init, nets, obs_dim)),
        act=jax.jit(functools.partial(_act, nets, cfg)),
        set_normalizer=make_normalizer_setter(obs_dim, time_feature=False),
        learn=functools.partial(_learn, _jitted(nets, cfg), cfg, obs_dim, action_dim),
        log_prob=jax.jit(functools.partial(_log_prob, nets, cfg)),
        value=jax.jit(functools.partial(_value_of, nets, cfg)),
    )
