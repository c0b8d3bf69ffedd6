"""Exact optimal transport by the network simplex (POT's ``ot.emd``)."""

from __future__ import annotations

import numpy as np

from ilfo.ot._checks import check_max_iter, check_problem, rebalance
from ilfo.ot.result import OTResult, make_result


def emd(
    cost: np.ndarray,
    a: np.ndarray | None = None,
    b: np.ndarray | None = None,
    max_iter: int = 10_000_000,
) -> OTResult:
    """Exact OT (earth mover's distance) by network simplex.

    Args:
        cost: Cost matrix, shape (n, m).
        a: Source weights, shape (n,); uniform if None.
        b: Target weights, shape (m,), same mass as a (to 1e-6 relative: it is rescaled to a's
            mass); uniform if None.
        max_iter: Most simplex pivots, an int >= 1; POT's default (100,000) is too few for
            1000 x 10000.

    Returns:
        An ``OTResult`` with the exact plan and the dual potentials; ``iterations`` is None
        (POT does not report it); ``converged`` is False if the pivot limit was hit.
    """
    import ot as pot  # here, not at import: POT's backends import torch, TF, ... where installed

    cost, a, b = check_problem(cost, a, b)
    max_iter = check_max_iter(max_iter)
    # POT rescales b to a's mass with a warning if they differ by rounding; make them agree.
    b = rebalance(a, b)
    plan, log = pot.emd(a, b, cost, numItermax=max_iter, log=True)
    return make_result(
        np.asarray(plan, dtype=np.float64),
        cost,
        a,
        b,
        f=np.asarray(log["u"], dtype=np.float64),
        g=np.asarray(log["v"], dtype=np.float64),
        iterations=None,
        converged=log["result_code"] == 1,
        solver="emd",
    )
