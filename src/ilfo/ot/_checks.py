"""Input validation shared by the solvers: clear ValueErrors instead of deep numpy failures."""

from __future__ import annotations

import numpy as np


def check_problem(
    cost: np.ndarray, a: np.ndarray | None, b: np.ndarray | None, *, balanced: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate a cost matrix (n, m) and weights; return float64 (cost, a, b).

    Missing weights become uniform. With ``balanced`` the masses of a and b must agree.
    """
    cost = np.asarray(cost, dtype=np.float64)
    if cost.ndim != 2:
        raise ValueError(f"cost matrix must be 2-D (n, m), got shape {cost.shape}")
    n, m = cost.shape
    if n == 0 or m == 0:
        raise ValueError(f"cost matrix must be non-empty, got shape {cost.shape}")
    # A finite sum proves every entry finite at a third of the cost of isfinite over the matrix.
    if not np.isfinite(cost.sum()) and not np.isfinite(cost).all():
        raise ValueError("cost matrix contains NaN or inf")
    a = _weights(a, n, "a")
    b = _weights(b, m, "b")
    if balanced and not np.isclose(a.sum(), b.sum(), rtol=1e-9, atol=1e-12):
        raise ValueError(f"weights must have equal mass: sum(a)={a.sum()!r}, sum(b)={b.sum()!r}")
    return cost, a, b


def _weights(w: np.ndarray | None, size: int, name: str) -> np.ndarray:
    if w is None:
        return np.full(size, 1.0 / size)
    w = np.asarray(w, dtype=np.float64)
    if w.shape != (size,):
        raise ValueError(f"weights {name} must have shape ({size},), got {w.shape}")
    if not np.isfinite(w).all():
        raise ValueError(f"weights {name} contain NaN or inf")
    if (w < 0).any() or w.sum() <= 0:
        raise ValueError(f"weights {name} must be non-negative with positive mass")
    return w
