"""Sinkhorn stays finite and accurate across regularisations and cost scales."""

import numpy as np
import pytest

from ilfo.ot import cost_matrix, sinkhorn


@pytest.mark.parametrize("reg", [1e-3, 1e-2, 0.05, 1.0, 10.0])
@pytest.mark.parametrize("scale", [0.01, 1.0, 100.0])
def test_sinkhorn_is_stable(reg, scale):
    rng = np.random.default_rng(0)
    cost = cost_matrix(rng.normal(size=(80, 5)), rng.normal(size=(90, 5)), "euclidean")
    cost *= scale / cost.mean()
    result = sinkhorn(cost, reg=reg, tol=1e-9, max_iter=20000)
    assert np.isfinite(result.plan).all()
    assert np.isfinite(result.f).all() and np.isfinite(result.g).all()
    n, m = cost.shape  # the verdict holds for the returned plan's own marginals
    error = np.abs(result.plan.sum(1) - 1 / n).sum() + np.abs(result.plan.sum(0) - 1 / m).sum()
    assert result.converged == (error < 1e-9)
    if reg / scale >= 1e-3:  # well-posed enough to converge within the budget
        assert result.converged, result.marginal_error


def test_non_convergence_is_data_not_an_exception():
    rng = np.random.default_rng(1)
    cost = cost_matrix(rng.normal(size=(50, 3)), rng.normal(size=(50, 3)))
    result = sinkhorn(cost, reg=1e-3, tol=1e-12, max_iter=3, acceleration="none")
    assert not result.converged
    assert result.iterations == 3
    assert result.marginal_error > 1e-12


def test_zero_weights_are_allowed():
    rng = np.random.default_rng(2)
    cost = cost_matrix(rng.normal(size=(4, 2)), rng.normal(size=(3, 2)))
    a = np.array([0.5, 0.0, 0.5, 0.0])
    result = sinkhorn(cost, a=a, tol=1e-12)
    assert result.converged
    assert (result.plan[[1, 3]] == 0).all()
    np.testing.assert_allclose(result.plan.sum(axis=1), a, atol=1e-12)


def test_result_is_immutable():
    result = sinkhorn(np.ones((3, 3)))
    with pytest.raises(ValueError):
        result.plan[0, 0] = 1.0
    with pytest.raises(AttributeError):
        result.cost = 0.0
