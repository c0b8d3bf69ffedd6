"""The numerics of TRPO's step (``ilfo.agents.trpo``), pure functions of arrays: diagonal Gaussian
densities and KL, the Fisher-vector product of a Gaussian policy, conjugate gradients and
generalised advantage estimates."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.signal
from numpy.typing import ArrayLike

from ilfo.networks import PairModule

Params = Any

_CG_RESIDUAL_TOL = 1e-10  # Khrylx's conjugate gradients stop once r.r falls below this
LOG_2PI = math.log(2.0 * math.pi)


def gaussian_log_prob(mean: jax.Array, log_std: jax.Array, action: jax.Array) -> jax.Array:
    """log N(action; mean, exp(log_std)^2) summed over the last axis: (..., d) -> (...)."""
    z = (action - mean) * jnp.exp(-log_std)
    return jnp.sum(-0.5 * z**2 - log_std - 0.5 * LOG_2PI, axis=-1)


def gaussian_kl(
    mean0: jax.Array, log_std0: jax.Array, mean1: jax.Array, log_std1: jax.Array
) -> jax.Array:
    """KL(N(mean0, std0^2) || N(mean1, std1^2)) of diagonal Gaussians, summed over the last
    axis: (..., d) -> (...)."""
    var_ratio = jnp.exp(2.0 * (log_std0 - log_std1))
    mahalanobis = ((mean0 - mean1) * jnp.exp(-log_std1)) ** 2
    return jnp.sum(log_std1 - log_std0 + 0.5 * (var_ratio + mahalanobis) - 0.5, axis=-1)


def fisher_vector_product(
    policy: PairModule,
    params: Params,
    obs_n: jax.Array,
    damping: float,
    code_fisher: bool = False,
) -> Callable[[Params], Params]:
    """v -> (F + damping I) v, F the Hessian at ``params`` of the mean over ``obs_n`` (N,
    obs_dim; normalised) of KL(pi_params || pi). For this Gaussian policy F is the analytic
    Fisher: (1/N) J^T diag(1/std^2) J on the mean network's parameters, 2 I on the log std and
    0 across (Khrylx's ``use_fim``). ``code_fisher``: also 2 I on the mean network's parameters,
    as the authors' code computes it (``TRPOConfig.code_fisher``). ``v`` is a pytree like
    ``params``."""
    mean_old, log_std_old = jax.lax.stop_gradient(policy.apply(params, obs_n))

    def mean_kl(p: Params) -> jax.Array:
        mean, log_std = policy.apply(p, obs_n)
        return jnp.mean(gaussian_kl(mean_old, log_std_old, mean, log_std))

    # linearize: the forward pass of grad(KL) is done once, and each product is its JVP.
    _, hvp = jax.linearize(jax.grad(mean_kl), params)

    def product(v: Params) -> Params:
        out = jax.tree.map(lambda fv, x: fv + damping * x, hvp(v), v)
        if code_fisher:
            mean = jax.tree.map(
                lambda fv, x: fv + 2.0 * x, out["params"]["mean"], v["params"]["mean"]
            )
            out = {"params": {**out["params"], "mean": mean}}
        return out

    return product


def conjugate_gradients(
    matvec: Callable[[jax.Array], jax.Array],
    b: jax.Array,
    iters: int,
    residual_tol: float = _CG_RESIDUAL_TOL,
) -> jax.Array:
    """Solve A x = b for a symmetric positive definite A given as ``matvec``, from x0 = 0: at
    most ``iters`` iterations, stopping once r.r < residual_tol (a ``lax.while_loop``)."""

    def cond(carry: tuple) -> jax.Array:
        i, _, _, _, rdotr = carry
        return (i < iters) & (rdotr >= residual_tol)

    def body(carry: tuple) -> tuple:
        i, x, r, p, rdotr = carry
        ap = matvec(p)
        alpha = rdotr / jnp.dot(p, ap)
        x = x + alpha * p
        r = r - alpha * ap
        new_rdotr = jnp.dot(r, r)
        p = r + (new_rdotr / rdotr) * p
        return i + 1, x, r, p, new_rdotr

    init = (jnp.array(0), jnp.zeros_like(b), b, b, jnp.dot(b, b))
    return jax.lax.while_loop(cond, body, init)[1]


def gae(
    rewards: ArrayLike, values: ArrayLike, episode_end: ArrayLike, gamma: float, lam: float
) -> np.ndarray:
    """Generalised advantage estimates (N,), float64, of concatenated episodes.

    delta_t = r_t + gamma * V_{t+1} * (1 - end_t) - V_t and A_t = delta_t + gamma * lam *
    (1 - end_t) * A_{t+1}: nothing flows across an episode end, so the last step of an episode
    (time limits included, as SIL's code) is not bootstrapped. The last step of the batch must
    be an episode end.
    """
    rewards = np.asarray(rewards, np.float64)
    values = np.asarray(values, np.float64)
    end = np.asarray(episode_end, bool)
    if not rewards.shape == values.shape == end.shape or rewards.ndim != 1 or not rewards.size:
        raise ValueError(
            "rewards, values and episode_end must be non-empty 1-D arrays of one length"
        )
    if not end[-1]:
        raise ValueError("the batch must end on an episode end")
    # Within an episode A is a discounted reverse cumulative sum of the deltas (factor gamma *
    # lam): a linear filter per episode, run backwards.
    next_values = np.append(values[1:], 0.0) * ~end
    deltas = rewards + gamma * next_values - values
    advantages = np.empty_like(deltas)
    starts = np.concatenate([[0], np.flatnonzero(end)[:-1] + 1])
    stops = np.flatnonzero(end) + 1
    for start, stop in zip(starts, stops, strict=True):
        segment = deltas[start:stop][::-1]
        advantages[start:stop] = scipy.signal.lfilter([1.0], [1.0, -gamma * lam], segment)[::-1]
    return advantages
