import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.distance import cdist

from ilfo.ot import METRICS, cost_matrix


@pytest.mark.parametrize(
    ("metric", "reference"),
    [
        ("euclidean", lambda x, y: cdist(x, y)),
        ("sqeuclidean", lambda x, y: cdist(x, y, "sqeuclidean")),
        ("sqrt_euclidean", lambda x, y: np.sqrt(cdist(x, y))),
        ("cosine", lambda x, y: cdist(x, y, "cosine")),
    ],
)
def test_costs_match_scipy(metric, reference):
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(20, 7)), rng.normal(size=(30, 7))
    np.testing.assert_allclose(cost_matrix(x, y, metric), reference(x, y), atol=1e-12)


@pytest.mark.parametrize("metric", METRICS)
def test_identical_points_cost_exactly_zero(metric):
    x = np.random.default_rng(1).normal(loc=100.0, size=(10, 5))  # large norms, tiny distances
    assert np.all(np.diag(cost_matrix(x, x, metric)) == 0.0)


def test_near_identical_points_keep_their_digits():
    x = np.random.default_rng(2).normal(loc=50.0, size=(8, 6))
    y = x + 1e-7
    expected = np.sqrt(cdist(x, y))
    np.testing.assert_allclose(cost_matrix(x, y), expected, rtol=1e-6)
    assert (cost_matrix(x, y, "sqeuclidean") >= 0).all()


@pytest.mark.parametrize("metric", METRICS)
def test_jax_costs_agree_and_have_finite_gradients_at_zero(metric):
    """At zero distance (x against itself), and at a zero vector (cosine's norm)."""
    x = np.random.default_rng(3).normal(size=(6, 3))
    x[0] = 0.0
    np.testing.assert_allclose(
        np.asarray(cost_matrix(jnp.asarray(x), jnp.asarray(x), metric)),
        cost_matrix(x, x, metric),
        atol=1e-6,
    )
    grad = jax.grad(lambda z: cost_matrix(z, jnp.asarray(x), metric).sum())(jnp.asarray(x))
    assert np.isfinite(np.asarray(grad)).all()


def test_bad_points_are_rejected():
    with pytest.raises(ValueError, match="dimensions differ"):
        cost_matrix(np.ones((2, 3)), np.ones((2, 4)))
    with pytest.raises(ValueError, match="2-D"):
        cost_matrix(np.ones(3), np.ones((2, 3)))
    with pytest.raises(ValueError, match="unknown metric"):
        cost_matrix(np.ones((2, 3)), np.ones((2, 3)), "manhattan")
