"""One entry to the couplings: ``solve(cost, "sinkhorn" | "emd" | "greedy", ...)``."""

from __future__ import annotations

from typing import Literal

import numpy as np

from ilfo.ot.emd import emd
from ilfo.ot.greedy import greedy
from ilfo.ot.result import OTResult
from ilfo.ot.sinkhorn import sinkhorn

Solver = Literal["sinkhorn", "emd", "greedy"]
SOLVERS: tuple[str, ...] = ("sinkhorn", "emd", "greedy")


def solve(
    cost: np.ndarray,
    solver: Solver = "sinkhorn",
    *,
    reg: float = 0.05,
    tol: float = 1e-9,
    max_iter: int = 20000,
    init: tuple[np.ndarray, np.ndarray] | None = None,
) -> OTResult:
    """The coupling of ``cost`` (n, m) between uniform weights by ``solver``: ``sinkhorn``
    (entropic OT with ``reg``, ``tol`` relative to the mass, an int ``max_iter`` and the warm
    start ``init``, all checked as ``ilfo.ot.sinkhorn`` does), ``emd`` (exact, network
    simplex) or ``greedy`` (PWIL's; rows in order). The Sinkhorn settings apply to Sinkhorn
    only."""
    if solver == "sinkhorn":
        return sinkhorn(cost, reg=reg, tol=tol, max_iter=max_iter, init=init)
    if solver == "emd":
        return emd(cost)
    if solver == "greedy":
        return greedy(cost)
    raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
