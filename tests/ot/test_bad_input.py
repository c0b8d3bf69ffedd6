import numpy as np
import pytest

from ilfo.ot import emd, greedy, sinkhorn

SOLVERS = [sinkhorn, emd, greedy]


@pytest.mark.parametrize("solve", SOLVERS)
@pytest.mark.parametrize(
    ("cost", "match"),
    [
        (np.ones(3), "2-D"),
        (np.ones((0, 3)), "non-empty"),
        (np.array([[1.0, np.nan]]), "NaN or inf"),
        (np.array([[1.0, np.inf]]), "NaN or inf"),
    ],
)
def test_bad_cost_matrices(solve, cost, match):
    with pytest.raises(ValueError, match=match):
        solve(cost)


@pytest.mark.parametrize("solve", SOLVERS)
def test_bad_weights(solve):
    cost = np.ones((2, 3))
    with pytest.raises(ValueError, match="shape"):
        solve(cost, a=np.ones(3))
    with pytest.raises(ValueError, match="non-negative"):
        solve(cost, a=np.array([1.5, -0.5]))


def test_unbalanced_weights_are_rejected_by_balanced_solvers():
    cost = np.ones((2, 2))
    for solve in (sinkhorn, emd):
        with pytest.raises(ValueError, match="equal mass"):
            solve(cost, a=np.array([0.5, 0.5]), b=np.array([0.5, 0.6]))


def test_bad_sinkhorn_parameters():
    cost = np.ones((2, 2))
    with pytest.raises(ValueError, match="reg"):
        sinkhorn(cost, reg=0.0)
    with pytest.raises(ValueError, match="init"):
        sinkhorn(cost, init=(np.zeros(3), np.zeros(2)))
    with pytest.raises(ValueError, match="acceleration"):
        sinkhorn(cost, acceleration="anderson")
