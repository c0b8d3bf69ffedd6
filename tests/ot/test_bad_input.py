import numpy as np
import pytest

from ilfo.ot import cost_matrix, emd, greedy, sinkhorn
from ilfo.ot import solve as dispatch

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
    for tol in (0.0, -1e-9, np.inf, np.nan):  # inf would stop at once and call it converged
        with pytest.raises(ValueError, match="tol must be a positive finite number"):
            sinkhorn(cost, tol=tol)


@pytest.mark.parametrize("solve", [sinkhorn, emd])
def test_float32_weights_are_accepted(solve):
    cost = np.random.default_rng(0).random((1000, 20))
    a = np.full(1000, 1e-3, np.float32)  # sums to 1 + 4.7e-8 in float64
    result = solve(cost, a=a)
    assert result.converged
    np.testing.assert_allclose(result.plan.sum(axis=1), a.astype(np.float64), rtol=1e-7)
    np.testing.assert_allclose(result.plan.sum(axis=0), a.astype(np.float64).sum() / 20)
    with pytest.raises(ValueError, match="equal mass"):
        solve(cost, a=a, b=np.full(20, (1 + 1e-5) / 20))


def test_warm_start_from_a_result_with_zero_weights():
    rng = np.random.default_rng(3)
    cost = cost_matrix(rng.normal(size=(5, 2)), rng.normal(size=(4, 2)))
    a = [0.5, 0.5, 0, 0, 0]
    first = sinkhorn(cost, a=a)
    assert np.isneginf(first.f[2:]).all()
    again = sinkhorn(cost, a=a, init=first.potentials)
    assert again.converged and again.iterations <= 2
    np.testing.assert_allclose(again.plan, first.plan, atol=1e-9)
    # On the support the potentials must still be finite; off it they are never read.
    with pytest.raises(ValueError, match="NaN or inf"):
        sinkhorn(cost, init=first.potentials)
    sinkhorn(cost, a=a, init=(np.array([0, 0, np.nan, np.inf, -np.inf]), np.zeros(4)))


@pytest.mark.parametrize("max_iter", [0, -3, 100.5, 1e4, True, "100", None])
def test_max_iter_must_be_a_positive_int(max_iter):
    cost = np.ones((2, 2))
    for call in (
        lambda: sinkhorn(cost, max_iter=max_iter),
        lambda: emd(cost, max_iter=max_iter),
        lambda: dispatch(cost, "sinkhorn", max_iter=max_iter),
    ):
        with pytest.raises(ValueError, match="max_iter must be an int >= 1"):
            call()


def test_a_huge_max_iter_allocates_nothing_for_it():
    cost = cost_matrix(np.eye(3), np.eye(3)[::-1])
    assert sinkhorn(cost, max_iter=10**12).converged
    assert dispatch(cost, "sinkhorn", max_iter=np.int64(10**12)).converged
    assert emd(cost, max_iter=np.int32(100)).converged


def test_solve_passes_the_sinkhorn_settings_through():
    cost = cost_matrix(np.eye(3), np.eye(3)[::-1] + 0.1)
    direct = sinkhorn(cost, reg=0.1, tol=1e-11, max_iter=500)
    routed = dispatch(cost, "sinkhorn", reg=0.1, tol=1e-11, max_iter=500, init=direct.potentials)
    assert routed.converged and routed.marginal_error < 1e-11
    np.testing.assert_allclose(routed.plan, direct.plan, atol=1e-10)
    with pytest.raises(ValueError, match="init"):
        dispatch(cost, init=(np.zeros(2), np.zeros(3)))
