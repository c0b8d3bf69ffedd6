"""Pairwise ground costs between two point clouds.

``cost_matrix`` accepts numpy arrays (returns numpy, float64) or JAX arrays (returns JAX, safe to
differentiate: the gradient of a root at zero distance is zero, not NaN), so that a learned
embedding (SIL, OOPS_adv) can use the same costs as the fixed rewarders.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

Metric = Literal["sqrt_euclidean", "euclidean", "sqeuclidean", "cosine"]
METRICS: tuple[str, ...] = get_args(Metric)

# Below this fraction of |x|^2 + |y|^2 the expansion |x|^2 + |y|^2 - 2 x.y loses its digits to
# cancellation, so such entries are recomputed from the difference x - y.
_CANCELLATION_RTOL = 1e-6


def cost_matrix(x, y, metric: Metric = "sqrt_euclidean"):
    """Pairwise costs C_ij = d(x_i, y_j).

    Args:
        x: Points, shape (n, d); numpy or JAX array.
        y: Points, shape (m, d); the same kind of array as ``x``.
        metric: ``sqrt_euclidean`` (sqrt of the Euclidean distance: the paper's default),
            ``euclidean``, ``sqeuclidean`` or ``cosine`` (1 - cosine similarity; a zero vector
            has similarity 0 with everything).

    Returns:
        Costs, shape (n, m), float64 for numpy input. Exact (0) for identical points.
    """
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    if _is_jax(x) or _is_jax(y):
        return _cost_matrix_jax(x, y, metric)
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    _check_points(x, y)
    if metric == "cosine":
        return _cosine_numpy(x, y)
    sq = squared_distances(x, y)
    if metric == "sqeuclidean":
        return sq
    np.sqrt(sq, out=sq)
    if metric == "sqrt_euclidean":
        np.sqrt(sq, out=sq)
    return sq


def squared_distances(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances, shape (n, m), never negative, exact near zero.

    Uses one matrix product (fast) and recomputes from differences the entries where the product
    form cancels (near-identical points), so that near-zero distances keep their digits.
    """
    xx = np.einsum("ij,ij->i", x, x)
    yy = np.einsum("ij,ij->i", y, y)
    sq = x @ y.T
    sq *= -2.0
    sq += xx[:, None]
    sq += yy[None, :]
    scale = xx[:, None] + yy[None, :]
    rows, cols = np.nonzero(sq <= _CANCELLATION_RTOL * scale)
    if rows.size:
        diff = x[rows] - y[cols]
        sq[rows, cols] = np.einsum("ij,ij->i", diff, diff)
    return sq


def _cosine_numpy(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    nx = np.linalg.norm(x, axis=1)
    ny = np.linalg.norm(y, axis=1)
    # For unit vectors 1 - cos = |x - y|^2 / 2, which keeps its digits for parallel vectors.
    dist = 0.5 * squared_distances(
        x / np.where(nx > 0, nx, 1.0)[:, None], y / np.where(ny > 0, ny, 1.0)[:, None]
    )
    dist[nx == 0, :] = 1.0  # a zero vector has similarity 0 with everything
    dist[:, ny == 0] = 1.0
    return np.clip(dist, 0.0, 2.0)


def _check_points(x: np.ndarray, y: np.ndarray) -> None:
    if x.ndim != 2 or y.ndim != 2:
        raise ValueError(f"points must be 2-D (n, d) and (m, d), got {x.shape} and {y.shape}")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"point dimensions differ: x has {x.shape[1]}, y has {y.shape[1]}")


def _is_jax(arr) -> bool:
    return type(arr).__module__.startswith(("jax", "jaxlib"))


def _cost_matrix_jax(x, y, metric: str):
    import jax.numpy as jnp

    if x.ndim != 2 or y.ndim != 2 or x.shape[1] != y.shape[1]:
        raise ValueError(f"points must be (n, d) and (m, d), got {x.shape} and {y.shape}")
    if metric == "cosine":
        # The norm's gradient at 0 is NaN, which a where after it does not stop: mask the
        # squared norm instead (a zero vector's norm is taken as 1: cost 1 to everything).
        sx = jnp.sum(x * x, axis=1, keepdims=True)
        sy = jnp.sum(y * y, axis=1, keepdims=True)
        safe_nx = jnp.sqrt(jnp.where(sx > 0, sx, 1.0))
        safe_ny = jnp.sqrt(jnp.where(sy > 0, sy, 1.0))
        return jnp.clip(1.0 - (x / safe_nx) @ (y / safe_ny).T, 0.0, 2.0)
    # Differences rather than the product expansion: exact at zero, and differentiable there.
    diff = x[:, None, :] - y[None, :, :]
    sq = jnp.sum(diff * diff, axis=-1)
    if metric == "sqeuclidean":
        return sq
    # Double-where: the root's gradient at 0 is infinite; mask it so that it becomes 0, not NaN.
    positive = sq > 0
    safe_sq = jnp.where(positive, sq, 1.0)
    root = 0.5 if metric == "euclidean" else 0.25
    return jnp.where(positive, safe_sq**root, 0.0)
