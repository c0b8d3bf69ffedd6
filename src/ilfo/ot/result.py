"""The one result type shared by every optimal-transport solver in ``ilfo.ot``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class OTResult:
    """An immutable optimal-transport solution.

    Non-convergence is data (``converged`` is False), never an exception or a warning.

    Attributes:
        plan: Coupling matrix, shape (n, m), non-negative.
        cost: Transport cost <C, plan>, a float.
        row_costs: Transported cost of each source atom, sum_j C_ij plan_ij, shape (n,).
            ``row_costs.sum() == cost``; rewarders turn it into per-step rewards.
        f: Source dual potential, shape (n,), or None where the solver has none (greedy).
        g: Target dual potential, shape (m,), or None where the solver has none (greedy).
        iterations: Solver iterations run (Sinkhorn updates of both potentials; 0 for greedy;
            None where the solver does not report a count, as POT's network simplex).
        converged: Whether the solver met its own stopping criterion (Sinkhorn: whether
            ``marginal_error < tol * sum(a)``, judged on this plan).
        marginal_error: L1 distance of both marginals to a and b,
            ``|plan.sum(1) - a|_1 + |plan.sum(0) - b|_1``, computed on the returned plan; absolute
            (in units of mass: divide by ``sum(a)`` for a relative error). b is the one the
            solver used: Sinkhorn and EMD rescale it to a's mass where the two differ by rounding.
        solver: The solver that made it, ``sinkhorn``, ``emd`` or ``greedy``.
    """

    plan: np.ndarray
    cost: float
    row_costs: np.ndarray
    f: np.ndarray | None
    g: np.ndarray | None
    iterations: int | None
    converged: bool
    marginal_error: float
    solver: str

    @property
    def potentials(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The dual potentials (f, g), or None where the solver has none."""
        if self.f is None or self.g is None:
            return None
        return self.f, self.g


def marginal_error(plan: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """L1 distance of the marginals of ``plan`` (n, m) to ``a`` (n,) and ``b`` (m,)."""
    return float(np.abs(plan.sum(axis=1) - a).sum() + np.abs(plan.sum(axis=0) - b).sum())


def make_result(
    plan: np.ndarray,
    cost_matrix: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    *,
    f: np.ndarray | None,
    g: np.ndarray | None,
    iterations: int | None,
    converged: bool,
    solver: str,
) -> OTResult:
    """Build an ``OTResult``, deriving the costs and the marginal error from ``plan``."""
    row_costs = np.einsum("ij,ij->i", cost_matrix, plan)
    plan.setflags(write=False)
    row_costs.setflags(write=False)
    return OTResult(
        plan=plan,
        cost=float(row_costs.sum()),
        row_costs=row_costs,
        f=f,
        g=g,
        iterations=iterations,
        converged=bool(converged),
        marginal_error=marginal_error(plan, a, b),
        solver=solver,
    )
