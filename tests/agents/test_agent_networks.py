"""Tests of the agents' networks (ilfo.networks)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ilfo.networks import (
    Critic,
    CriticEnsemble,
    DeterministicActor,
    SquashedGaussianActor,
)


def test_critic_ensemble_is_vmapped_critics():
    obs, act = jnp.ones((5, 3)), jnp.ones((5, 2))
    ens = CriticEnsemble((8, 8), num_critics=3)
    params = ens.init(jax.random.PRNGKey(0), obs, act)
    kernel = params["params"]["ensemble"]["MLP_0"]["Dense_0"]["kernel"]
    assert kernel.shape == (3, 5, 8)
    assert not np.allclose(kernel[0], kernel[1])  # members initialised independently
    q = ens.apply(params, obs, act)
    assert q.shape == (3, 5)
    for i in range(3):  # member i is a plain Critic with the i-th slice of the parameters
        member = jax.tree.map(lambda p, i=i: p[i], params["params"]["ensemble"])
        qi = Critic((8, 8)).apply({"params": member}, obs, act)
        np.testing.assert_allclose(np.asarray(qi), np.asarray(q[i]), rtol=1e-6)
    first = CriticEnsemble((8, 8), 1).apply(jax.tree.map(lambda p: p[:1], params), obs, act)
    np.testing.assert_allclose(np.asarray(first[0]), np.asarray(q[0]), rtol=1e-6)
    assert ens.apply(params, obs[0], act[0]).shape == (3,)  # unbatched input


def test_actors_shapes_and_bounds():
    obs = jax.random.normal(jax.random.PRNGKey(0), (7, 4)) * 100
    actor = DeterministicActor((8,), action_dim=2, max_action=3.0)
    params = actor.init(jax.random.PRNGKey(1), obs)
    a = actor.apply(params, obs)
    assert a.shape == (7, 2) and np.all(np.abs(np.asarray(a)) <= 3.0)
    gauss = SquashedGaussianActor((8,), action_dim=2, log_std_min=-5.0, log_std_max=1.0)
    mean, log_std = gauss.apply(gauss.init(jax.random.PRNGKey(2), obs), obs)
    assert mean.shape == log_std.shape == (7, 2)
    assert np.all((np.asarray(log_std) >= -5.0) & (np.asarray(log_std) <= 1.0))


def test_torch_init_is_pytorch_linear_default():
    obs, act = jnp.ones((5, 30)), jnp.ones((5, 2))
    params = CriticEnsemble((400, 300), num_critics=2, init_scheme="torch").init(
        jax.random.PRNGKey(0), obs, act
    )["params"]["ensemble"]["MLP_0"]
    for name, fan_in in (("Dense_0", 32), ("Dense_1", 400), ("Dense_2", 300)):
        bound = 1.0 / np.sqrt(fan_in)
        for leaf in ("kernel", "bias"):
            w = np.asarray(params[name][leaf])
            assert np.all(np.abs(w) <= bound)
            if w.size >= 100:  # uniform on [-bound, bound]: std bound / sqrt(3), biases too
                np.testing.assert_allclose(w.std(), bound / np.sqrt(3), rtol=0.1)
    flax_default = CriticEnsemble((400, 300), num_critics=2).init(jax.random.PRNGKey(0), obs, act)
    assert not np.any(flax_default["params"]["ensemble"]["MLP_0"]["Dense_0"]["bias"])


def test_critic_layer_norm_normalises_each_hidden_layer_and_is_off_by_default():
    from ilfo.networks import MLP

    x = jax.random.normal(jax.random.PRNGKey(0), (5, 3)) * 100.0
    plain, normed = MLP((8, 8), 1), MLP((8, 8), 1, layer_norm=True)
    assert "LayerNorm_0" not in plain.init(jax.random.PRNGKey(1), x)["params"]
    params = normed.init(jax.random.PRNGKey(1), x)
    assert {"LayerNorm_0", "LayerNorm_1"} <= set(params["params"])
    # Each hidden layer's pre-activation has zero mean and unit variance per sample, so inputs
    # 100x larger give (almost) the same output: without the norm they would not.
    np.testing.assert_allclose(
        normed.apply(params, x), normed.apply(params, x * 100.0), rtol=1e-3, atol=1e-3
    )
    plain_params = plain.init(jax.random.PRNGKey(1), x)
    assert not np.allclose(plain.apply(plain_params, x), plain.apply(plain_params, x * 100.0))
