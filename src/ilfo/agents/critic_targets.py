"""The pieces of a TD3-style critic update that TD3, TD7 and OPOLO share: the critic's loss of
its TD errors (PAL, MSE, Huber) and the time augmentation of its batches (the OOPS paper's
code), each a pure function of arrays."""

from __future__ import annotations

from typing import Literal

import jax
import jax.numpy as jnp
import optax

LossName = Literal["pal", "mse", "huber"]
TimeAugmentationScheme = Literal["finite_horizon", "next_only"]


def pal_loss(td: jax.Array, alpha: float = 0.4, min_priority: float = 1.0) -> jax.Array:
    """Prioritised approximation loss (Fujimoto, Meger, Precup 2020), as in the authors' code.

    td: (num_critics, B) TD errors Q_i(s, a) - y. Returns a scalar:

        sum_i mean_b f(td_ib) / stop_gradient(mean_b max(max_i |td_ib|, m)^alpha)

    with m = min_priority and f(x) = m^alpha * x^2 / 2 if |x| < m, else
    m * |x|^(1 + alpha) / (1 + alpha). The gradient of f is continuous at |x| = m and equals
    that of the Huber loss (threshold m) weighted by LAP's priority max(|x|, m)^alpha, which is
    what makes PAL with uniform sampling equivalent in expectation to LAP. For m = 1 (the
    paper's and OOPS's setting) f is the paper's 0.5 x^2 / |x|^(1+alpha) / (1+alpha); for
    m != 1 the scaling follows the authors' code (sfujim/LAP-PAL), which keeps f' continuous.
    The priority of a sample is taken from the larger |td| of the critics, as in that code.
    """
    abs_td = jnp.abs(td)
    per_sample = jnp.where(
        abs_td < min_priority,
        min_priority**alpha * 0.5 * td**2,
        min_priority * abs_td ** (1.0 + alpha) / (1.0 + alpha),
    )
    normaliser = jnp.mean(jnp.maximum(jnp.max(abs_td, axis=0), min_priority) ** alpha)
    return jnp.sum(jnp.mean(per_sample, axis=-1)) / jax.lax.stop_gradient(normaliser)


def critic_loss(
    td: jax.Array, loss: LossName, pal_alpha: float = 0.4, pal_min_priority: float = 1.0
) -> jax.Array:
    """Critic loss of TD errors td (num_critics, B) -> scalar; summed over critics."""
    if loss == "pal":
        return pal_loss(td, pal_alpha, pal_min_priority)
    if loss == "mse":
        return jnp.sum(jnp.mean(td**2, axis=-1))
    if loss == "huber":
        return jnp.sum(jnp.mean(optax.huber_loss(td, delta=1.0), axis=-1))
    raise ValueError(f"unknown loss {loss!r}")


def augment_time(
    key: jax.Array, obs: jax.Array, next_obs: jax.Array, max_time: int
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Time augmentation of a critic batch, as the OOPS paper's code does it.

    Draws a time-to-go k ~ U{1, ..., max_time} per row and sets the last feature (the time) of
    ``obs`` (B, d) to k / max_time and of ``next_obs`` to (k - 1) / max_time; the transition
    ends the episode exactly when k = 1. Returns (obs, next_obs, not_done (B,)).

    Every stored transition thus trains the critic's finite-horizon backup
    Q(s, a, k) = r + gamma * Q(s', a', k - 1) at a random k, not only at its recorded time, so
    the critic is defined at every (state, time) pair its targets query. The recorded
    termination flag is not used: this is only valid for fixed-horizon episodes, in which
    termination never cuts an episode short (the trainer enables it only there).
    """
    k = jax.random.randint(key, obs.shape[:-1], 1, max_time + 1).astype(obs.dtype)
    obs = obs.at[..., -1].set(k / max_time)
    next_obs = next_obs.at[..., -1].set((k - 1.0) / max_time)
    return obs, next_obs, (k > 1.0).astype(obs.dtype)


def redraw_next_time(key: jax.Array, next_obs: jax.Array, max_time: int) -> jax.Array:
    """The reference notes' time augmentation: the last feature (the time) of ``next_obs``
    (B, d) set to k / max_time with k ~ U{1, ..., max_time} per row; everything else, the
    current time and the end-of-episode flag included, stays as recorded. The TD target then
    queries the critic at a random time-to-go while the critic is trained at the recorded one,
    which is not a finite-horizon backup (``augment_time`` is)."""
    k = jax.random.randint(key, next_obs.shape[:-1], 1, max_time + 1).astype(next_obs.dtype)
    return next_obs.at[..., -1].set(k / max_time)
