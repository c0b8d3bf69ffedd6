"""Optimal transport on arrays: costs, solvers (Sinkhorn, exact EMD, greedy) and their result.

Knows nothing of RL. Every solver takes a cost matrix (n, m) and optional weights a (n,), b (m,)
(uniform by default) and returns the same immutable :class:`OTResult`.
"""

from ilfo.ot.costs import METRICS, Metric, cost_matrix
from ilfo.ot.emd import emd
from ilfo.ot.greedy import greedy
from ilfo.ot.result import OTResult, marginal_error
from ilfo.ot.sinkhorn import sinkhorn

__all__ = [
    "METRICS",
    "Metric",
    "OTResult",
    "cost_matrix",
    "emd",
    "greedy",
    "marginal_error",
    "sinkhorn",
]
