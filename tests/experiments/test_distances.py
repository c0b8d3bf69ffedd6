"""Table 3's distances: atoms per space, exact W1 against POT and a closed form."""

from __future__ import annotations

import numpy as np
import pytest

import ot as pot
from ilfo.experiments.distances import Trajectory, atoms, distances, wasserstein


def _trajectory(rng, steps=30, obs_dim=3, act_dim=2, shift=0.0):
    return Trajectory(
        rng.normal(size=(steps + 1, obs_dim)) + shift, rng.normal(size=(steps, act_dim))
    )


def test_atoms_per_space():
    t = _trajectory(np.random.default_rng(0))
    assert atoms(t, "s").shape == (30, 3)
    assert atoms(t, "s,s'").shape == (30, 6)
    np.testing.assert_array_equal(atoms(t, "s,s'")[:, 3:], t.observations[1:])
    assert atoms(t, "s,a").shape == (30, 5)
    np.testing.assert_array_equal(atoms(t, "s,a")[:, 3:], t.actions)
    with pytest.raises(ValueError, match="space"):
        atoms(t, "a")
    with pytest.raises(ValueError, match="one more observation"):
        Trajectory(np.zeros((5, 3)), np.zeros((5, 2)))


def test_wasserstein_against_pot_and_a_translation():
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=(40, 4)), rng.normal(size=(25, 4)) + 1.0
    reference = pot.emd2(np.full(40, 1 / 40), np.full(25, 1 / 25), pot.dist(x, y, "euclidean"))
    assert wasserstein(x, y) == pytest.approx(reference, rel=1e-9)
    # W1 of a point cloud and its translate by v is |v| (the shift is optimal, and Jensen bounds
    # every coupling below by |mean difference|).
    v = np.array([0.3, -1.2, 0.5, 2.0])
    assert wasserstein(x, x + v) == pytest.approx(np.linalg.norm(v), rel=1e-9)
    assert wasserstein(x, x) == pytest.approx(0.0, abs=1e-12)


def test_distances_average_over_pairs():
    rng = np.random.default_rng(2)
    rollouts = [_trajectory(rng) for _ in range(2)]
    experts = [_trajectory(rng, shift=1.0) for _ in range(3)]
    out = distances(rollouts, experts)
    pairs = [wasserstein(atoms(r, "s"), atoms(e, "s")) for r in rollouts for e in experts]
    assert out["s"] == pytest.approx(np.mean(pairs))
    assert out["s,s'"] > out["s"] > 0  # more coordinates apart, larger distance
    with pytest.raises(ValueError, match="at least one"):
        distances([], experts)


def test_solver_costs_bound_the_exact_one():
    from ilfo.experiments.distances import solver_distances

    rng = np.random.default_rng(3)
    rollouts = [_trajectory(rng, steps=20) for _ in range(2)]
    experts = [_trajectory(rng, steps=25, shift=0.5)]
    out = solver_distances(rollouts, experts, lambdas=(0.01, 0.1, 1.0))
    exact = np.mean(
        [wasserstein(atoms(r, "s,s'"), atoms(e, "s,s'")) for r in rollouts for e in experts]
    )
    assert out["W_simplex"] == pytest.approx(exact)
    assert out["W_greedy"] >= exact - 1e-9
    sinkhorn = [out[f"W_Sk({lam:g})"] for lam in (0.01, 0.1, 1.0)]
    assert all(s >= exact - 1e-6 for s in sinkhorn)
    assert sinkhorn == sorted(sinkhorn)  # more entropy, a looser plan
    assert out["converged(0.1)"] == 1.0
