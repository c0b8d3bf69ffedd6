"""PWIL's greedy coupling (Dadashi et al. 2021, "Primal Wasserstein Imitation Learning")."""

from __future__ import annotations

import numpy as np

from ilfo.ot._checks import check_problem
from ilfo.ot.result import OTResult, make_result

# Masses below this fraction of the total count as spent: guards the loop against rounding
# leftovers (1e-19 of a mass 1), whatever the scale of the weights.
_MASS_RTOL = 1e-14
# The placed mass may differ from sum(a) by this much (relative) and still count as all placed.
_PLACED_RTOL = 1e-9


def greedy(cost: np.ndarray, a: np.ndarray | None = None, b: np.ndarray | None = None) -> OTResult:
    """Greedy coupling: source atoms in order, each takes its mass from the cheapest target atoms
    that still have mass, as PWIL does online along an episode.

    Args:
        cost: Cost matrix, shape (n, m); rows are taken in order.
        a: Source weights, shape (n,); uniform if None. sum(a) may be below sum(b) (PWIL gives
            each learner step 1/horizon, so a short episode moves less than all the mass).
        b: Target weights, shape (m,); uniform if None.

    Returns:
        An ``OTResult``; no potentials; ``converged`` is True when all of a was placed.
    """
    cost, a, b = check_problem(cost, a, b, balanced=False)
    if a.sum() > b.sum() * (1 + 1e-9):
        raise ValueError(f"greedy needs sum(a) <= sum(b), got {a.sum()!r} > {b.sum()!r}")
    n, m = cost.shape
    eps = _MASS_RTOL * b.sum()
    plan = np.zeros((n, m))
    left = b.copy()
    # +inf marks spent target atoms, so argmin skips them without re-sorting rows.
    spent = np.where(left > eps, 0.0, np.inf)
    for i in range(n):
        need = a[i]
        if need <= eps:
            continue
        row = cost[i] + spent
        while need > eps:
            j = int(np.argmin(row))
            if not np.isfinite(row[j]):
                break  # nothing left anywhere
            take = min(need, left[j])
            plan[i, j] += take
            need -= take
            left[j] -= take
            if left[j] <= eps:
                row[j] = spent[j] = np.inf
    all_placed = abs(plan.sum() - a.sum()) <= _PLACED_RTOL * a.sum()
    return make_result(
        plan, cost, a, b, f=None, g=None, iterations=0, converged=all_placed, solver="greedy"
    )
