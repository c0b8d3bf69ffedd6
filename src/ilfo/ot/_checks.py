"""Input validation shared by the solvers: clear ValueErrors instead of deep numpy failures."""

from __future__ import annotations

import numpy as np

# Masses may differ by this much (relative) and still count as equal: float32 weights (1e-3 each,
# stored in float32) sum to 1 +- 5e-8 in float64; unequal masses are a bug, refused.
MASS_RTOL = 1e-6


def check_problem(
    cost: np.ndarray, a: np.ndarray | None, b: np.ndarray | None, *, balanced: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate a cost matrix (n, m) and weights; return float64 (cost, a, b).

    Missing weights become uniform. With ``balanced`` the masses of a and b must agree to
    ``MASS_RTOL`` (rounding, e.g. float32 weights); solvers that need them exactly equal rescale
    b (``rebalance``).
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
    if balanced and not abs(a.sum() - b.sum()) <= MASS_RTOL * max(a.sum(), b.sum()):
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


def rebalance(a: np.ndarray, b: np.ndarray, rtol: float = 0.0) -> np.ndarray:
    """b rescaled to a's mass where they differ by more than ``rtol`` (relative), else b itself.

    Balanced solvers need equal masses exactly: a mismatch d leaves an L1 marginal error >= |d|
    that no iteration removes. ``rtol`` leaves alone the few-ulp differences between sums of
    uniform weights, so that those results stay bit-identical.
    """
    mass_a, mass_b = a.sum(), b.sum()
    if abs(mass_a - mass_b) <= rtol * mass_a:
        return b
    return b * (mass_a / mass_b)


def check_max_iter(max_iter: int) -> int:
    """An iteration limit: an int >= 1 (a float such as 1e4 or 100.5 is refused, not truncated)."""
    return check_count(max_iter, "max_iter")


def check_count(value: int, name: str) -> int:
    """A count named ``name``: an int >= 1 (a bool, or a float such as 1e4, is refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an int >= 1, got {value!r}")
    return int(value)
