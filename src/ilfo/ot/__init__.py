"""Optimal transport on arrays: costs, solvers (Sinkhorn, exact EMD, greedy) and their result.

Knows nothing of RL. Every solver takes a cost matrix (n, m) and optional weights a (n,), b (m,)
(uniform by default) and returns the same immutable ``OTResult``; ``solve(cost, solver)``
is the one dispatch between them by name.
"""

from ilfo.ot.costs import METRICS, Metric, cost_matrix
from ilfo.ot.emd import emd
from ilfo.ot.greedy import greedy
from ilfo.ot.result import OTResult, marginal_error
from ilfo.ot.sinkhorn import sinkhorn
from ilfo.ot.solve import SOLVERS, Solver, solve

__all__ = [
    "METRICS",
    "SOLVERS",
    "Metric",
    "OTResult",
    "Solver",
    "cost_matrix",
    "emd",
    "greedy",
    "marginal_error",
    "sinkhorn",
    "solve",
]
