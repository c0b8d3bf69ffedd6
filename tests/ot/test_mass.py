"""Sinkhorn's tol is relative to the mass of the weights, and mass-1 results did not move for it."""

import importlib

import numpy as np
import pytest

from ilfo.ot import cost_matrix, sinkhorn

_sinkhorn_module = importlib.import_module("ilfo.ot.sinkhorn")


def _problem(n, m, seed, near=False):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 4))
    y = x[:m] + 0.01 * rng.normal(size=(m, 4)) if near else rng.normal(size=(m, 4))
    return cost_matrix(x, y)


_CASES = {
    "plain": (dict(n=30, m=20, seed=0), dict(reg=0.05)),
    "overrelax": (dict(n=37, m=53, seed=1), dict(reg=0.01, tol=1e-12, acceleration="overrelax")),
    "none": (dict(n=7, m=9, seed=2), dict(reg=0.05, acceleration="none")),
    "newton": (dict(n=120, m=100, seed=3, near=True), dict(reg=0.01)),
    "short": (dict(n=30, m=20, seed=0), dict(reg=0.01, max_iter=7)),
    "zero_weight": (dict(n=5, m=6, seed=4), dict(a=[0.5, 0.5, 0, 0, 0])),
}
# (iterations, converged, cost, marginal_error) recorded before tol became relative to the mass
# (at cba085b); the plans, potentials and flags were then bit-identical on this project's
# machines. Costs are compared to 1e-13 (not bit for bit) so that another BLAS may round otherwise.
_BEFORE = {
    "plain": (52, True, 1.197056513241814, 4.212445808837728e-10),
    "overrelax": (172, True, 1.0625854021089036, 9.91418752649409e-13),
    "none": (117, True, 1.3246408004313024, 9.829627112267758e-10),
    "newton": (59, True, 0.3009084389044188, 4.916538461074982e-10),
    "short": (7, False, 1.138459622376303, 0.43757810451598406),
    "zero_weight": (23, True, 1.5882803785668798, 7.221196696161059e-10),
}


@pytest.mark.parametrize("case", sorted(_CASES))
def test_mass_one_results_are_unchanged(case):
    problem, kwargs = _CASES[case]
    result = sinkhorn(_problem(**problem), **kwargs)
    iterations, converged, cost, error = _BEFORE[case]
    assert (result.iterations, result.converged) == (iterations, converged)
    assert result.cost == pytest.approx(cost, rel=1e-13)
    assert result.marginal_error == pytest.approx(error, rel=1e-5)


@pytest.mark.parametrize("mass", [1e-6, 1e6, 1e8])
@pytest.mark.parametrize("acceleration", ["none", "newton"])
def test_scaling_the_weights_scales_nothing_else(mass, acceleration):
    cost = _problem(40, 30, seed=5)
    a, b = np.full(40, 1 / 40), np.full(30, 1 / 30)
    unit = sinkhorn(cost, a=a, b=b, acceleration=acceleration)
    scaled = sinkhorn(cost, a=a * mass, b=b * mass, acceleration=acceleration)
    assert unit.converged and scaled.converged
    assert scaled.iterations == unit.iterations
    assert scaled.marginal_error < 1e-9 * mass
    np.testing.assert_allclose(scaled.plan / mass, unit.plan, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(scaled.cost / mass, unit.cost, rtol=1e-12)


@pytest.mark.parametrize("mass", [1.0, 1e6])
@pytest.mark.parametrize(
    ("acceleration", "problem", "reg", "budgets"),
    [
        ("none", dict(n=40, m=30, seed=5), 0.05, range(1, 200, 2)),
        ("newton", dict(n=120, m=100, seed=3, near=True), 0.01, range(1, 80, 3)),
    ],
)
def test_converged_agrees_with_the_reported_marginal_error(
    mass, acceleration, problem, reg, budgets, monkeypatch
):
    newton_steps = []
    newton = _sinkhorn_module._newton

    def counting_newton(*args):
        out = newton(*args)
        newton_steps.append(out[2])
        return out

    monkeypatch.setattr(_sinkhorn_module, "_newton", counting_newton)
    cost = _problem(**problem)
    n, m = cost.shape
    a, b = np.full(n, mass / n), np.full(m, mass / m)
    tol = 1e-9
    for max_iter in [*budgets, 20000]:
        result = sinkhorn(
            cost, a=a, b=b, reg=reg, tol=tol, max_iter=max_iter, acceleration=acceleration
        )
        # Recomputed here from the returned plan: the verdict must hold for the plan one gets,
        # not for the loop's last (Sinkhorn- or Newton-side) estimate.
        error = np.abs(result.plan.sum(1) - a).sum() + np.abs(result.plan.sum(0) - b).sum()
        assert result.marginal_error == pytest.approx(error, rel=1e-9, abs=1e-15 * mass)
        assert result.converged == (error < tol * mass), (max_iter, result)
    assert result.converged
    assert (sum(newton_steps) > 0) == (acceleration == "newton")  # Newton's path judged too
