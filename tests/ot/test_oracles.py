"""Solvers against independent oracles: scipy's assignment, POT's Sinkhorn, and each other."""

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

import ot as pot
from ilfo.ot import cost_matrix, emd, greedy, sinkhorn


def _points(n, m, d=6, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, d)), rng.normal(size=(m, d))


@pytest.mark.parametrize("n", [1, 5, 40])
def test_emd_equals_linear_sum_assignment_on_square_uniform(n):
    x, y = _points(n, n, seed=n)
    cost = cost_matrix(x, y, "euclidean")
    rows, cols = linear_sum_assignment(cost)
    result = emd(cost)
    assert result.converged
    assert result.cost == pytest.approx(cost[rows, cols].sum() / n, rel=1e-12, abs=1e-14)
    assert result.marginal_error < 1e-12


@pytest.mark.parametrize("reg", [0.05, 0.5, 2.0])
@pytest.mark.parametrize("shape", [(30, 30), (20, 45)])
def test_sinkhorn_equals_pot(reg, shape):
    x, y = _points(*shape, seed=1)
    cost = cost_matrix(x, y)
    a = np.full(shape[0], 1 / shape[0])
    b = np.full(shape[1], 1 / shape[1])
    expected = pot.sinkhorn(
        a, b, cost, reg, method="sinkhorn_log", stopThr=1e-13, numItermax=100000
    )
    result = sinkhorn(cost, reg=reg, tol=1e-12)
    assert result.converged
    np.testing.assert_allclose(result.plan, expected, atol=1e-8, rtol=0)


@pytest.mark.parametrize("acceleration", ["none", "overrelax", "newton"])
def test_every_acceleration_reaches_the_same_plan(acceleration):
    x, y = _points(60, 50, seed=2)
    cost = cost_matrix(x, y)
    reference = sinkhorn(cost, reg=0.05, tol=1e-12, acceleration="none", max_iter=200000)
    result = sinkhorn(cost, reg=0.05, tol=1e-12, acceleration=acceleration, max_iter=200000)
    assert reference.converged and result.converged
    np.testing.assert_allclose(result.plan, reference.plan, atol=1e-10, rtol=0)


def test_newton_converges_on_an_ill_conditioned_near_expert_problem():
    # A trajectory-like chain of atoms matched to a noisy copy of itself: plain Sinkhorn crawls.
    rng = np.random.default_rng(3)
    expert = np.cumsum(rng.normal(scale=0.1, size=(120, 4)), axis=0)
    learner = expert + rng.normal(scale=0.01, size=expert.shape)
    cost = cost_matrix(learner, expert)
    plain = sinkhorn(cost, reg=0.05, tol=1e-8, max_iter=300, acceleration="none")
    newton = sinkhorn(cost, reg=0.05, tol=1e-8, max_iter=300, acceleration="newton")
    assert not plain.converged
    assert newton.converged and newton.marginal_error < 1e-8
    # The optimum is the Gibbs plan exp((f + g - C) / reg) with the right marginals.
    gibbs = np.exp((newton.f[:, None] + newton.g[None, :] - cost) / 0.05)
    np.testing.assert_allclose(newton.plan, gibbs, rtol=1e-9, atol=1e-300)
    long_plain = sinkhorn(cost, reg=0.05, tol=1e-10, max_iter=400000, acceleration="none")
    assert long_plain.converged
    np.testing.assert_allclose(newton.plan, long_plain.plan, atol=1e-8, rtol=0)


@pytest.mark.parametrize("episode", [6, 7, 9])
def test_newton_converges_between_two_episodes_of_the_same_expert(episode):
    # The shipped Hopper expert's demos 6, 7 and 9 against demo 0 as OOPS couples them: Newton's
    # first step must be damped (4.3e-3 -> 2.9e-3 for demo 6), the next ones converge
    # quadratically. Giving up Newton after that first step left plain Sinkhorn at 20,000
    # iterations, unconverged (minutes per episode).
    from ilfo import demos
    from ilfo.paths import DATA_DIR
    from ilfo.rewards import OOPS
    from ilfo.rewards.base import make_atoms

    episodes = demos.load(DATA_DIR / "experts" / "Hopper-v5" / "demos.npz").episodes
    oops = OOPS([episodes[0].observations])
    learner = make_atoms(oops.standardizer(episodes[episode].observations), "transitions")
    cost = cost_matrix(learner, oops.expert_atoms[0], "sqrt_euclidean")
    result = sinkhorn(cost, reg=0.05, tol=1e-9, max_iter=300)
    assert result.converged and result.marginal_error < 1e-9
    gibbs = np.exp((result.f[:, None] + result.g[None, :] - cost) / 0.05)
    np.testing.assert_allclose(result.plan, gibbs, rtol=1e-9, atol=1e-300)


def test_sinkhorn_cost_tends_to_emd_cost_as_reg_shrinks():
    x, y = _points(40, 40, seed=4)
    cost = cost_matrix(x, y)
    exact = emd(cost).cost
    gaps = [
        sinkhorn(cost, reg=reg, tol=1e-10, max_iter=200000).cost - exact
        for reg in (1.0, 0.1, 0.01, 0.002)
    ]
    assert all(g >= -1e-9 for g in gaps)  # the entropic plan is feasible, so never below EMD
    assert all(later < earlier for earlier, later in itertools.pairwise(gaps))
    assert gaps[-1] < 1e-2 * exact


def test_warm_start_from_own_potentials_converges_at_once():
    x, y = _points(50, 70, seed=5)
    cost = cost_matrix(x, y)
    cold = sinkhorn(cost, tol=1e-10)
    warm = sinkhorn(cost, tol=1e-10, init=cold.potentials)
    assert warm.converged and warm.iterations <= 2
    np.testing.assert_allclose(warm.plan, cold.plan, atol=1e-12)


def test_greedy_follows_rows_in_order():
    # Two learner atoms both nearest to expert atom 0: the first takes it, the second gets atom 1.
    cost = np.array([[0.0, 1.0], [0.0, 5.0]])
    result = greedy(cost)
    np.testing.assert_allclose(result.plan, [[0.5, 0.0], [0.0, 0.5]])
    assert result.f is None and result.potentials is None and result.converged


def test_greedy_splits_mass_across_expert_atoms():
    cost = np.array([[0.0, 1.0, 2.0]])  # one learner atom of mass 1, three expert atoms of 1/3
    result = greedy(cost)
    np.testing.assert_allclose(result.plan, [[1 / 3, 1 / 3, 1 / 3]])
    assert result.cost == pytest.approx(1.0)


@pytest.mark.parametrize("mass", [1e-16, 1e8])
def test_greedy_scales_with_the_weights(mass):
    # Its thresholds are relative to the mass: at 1e-16 every atom used to count as already
    # spent (an empty plan called converged), at 1e8 rounding leftovers as unspent.
    rng = np.random.default_rng(1)
    cost = rng.random((40, 60))
    a, b = rng.random(40), rng.random(60)
    a, b = a / a.sum() * 0.7, b / b.sum()  # PWIL's case: a short episode moves less than b
    unit = greedy(cost, a, b)
    scaled = greedy(cost, a * mass, b * mass)
    assert unit.converged and scaled.converged
    np.testing.assert_allclose(scaled.plan / mass, unit.plan, rtol=1e-9, atol=1e-15)
    assert np.count_nonzero(scaled.plan) == np.count_nonzero(unit.plan)


def test_solve_dispatches_to_each_solver_by_name():
    from ilfo.ot import emd, greedy, sinkhorn, solve

    rng = np.random.default_rng(0)
    cost = rng.random((6, 5))
    np.testing.assert_array_equal(solve(cost).plan, sinkhorn(cost).plan)
    np.testing.assert_array_equal(
        solve(cost, "sinkhorn", reg=0.2).plan, sinkhorn(cost, reg=0.2).plan
    )
    np.testing.assert_array_equal(solve(cost, "emd").plan, emd(cost).plan)
    np.testing.assert_array_equal(solve(cost, "greedy").plan, greedy(cost).plan)
    with pytest.raises(ValueError, match="solver must be one of sinkhorn, emd, greedy"):
        solve(cost, "auction")
