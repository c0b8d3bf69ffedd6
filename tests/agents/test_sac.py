"""Tests of SAC (ilfo.agents.sac) and the squashed Gaussian policy it uses."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from agent_helpers import ACT_DIM, MAX_ACTION, OBS_DIM, TINY, random_buffer

from ilfo.agents import SACConfig, make_sac
from ilfo.networks import sample_squashed


def leaves_equal(a, b) -> bool:
    return all(
        np.array_equal(np.asarray(x), np.asarray(y))
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


def test_defaults_follow_haarnoja_2018():
    c = SACConfig()
    assert c.actor_hidden == c.critic_hidden == (256, 256)
    assert (c.lr_actor, c.lr_critic, c.lr_temperature) == (3e-4, 3e-4, 3e-4)
    assert (c.batch_size, c.tau, c.gamma, c.num_critics) == (256, 0.005, 0.99, 2)
    assert c.autotune and c.target_entropy is None  # -action_dim


def test_squashed_log_prob_change_of_variables():
    key = jax.random.PRNGKey(0)
    mean = jnp.array([[0.3, -1.0], [2.0, 0.0]])
    log_std = jnp.array([[-0.5, 0.2], [0.0, -1.0]])
    action, logp = sample_squashed(key, mean, log_std, 2.0)
    # Recover u from the action and apply the change of variables directly.
    u = jnp.arctanh(action / 2.0)
    std = jnp.exp(log_std)
    gauss = -0.5 * ((u - mean) / std) ** 2 - log_std - 0.5 * jnp.log(2 * jnp.pi)
    expected = jnp.sum(gauss - jnp.log(2.0 * (1 - jnp.tanh(u) ** 2)), axis=-1)
    np.testing.assert_allclose(np.asarray(logp), np.asarray(expected), rtol=1e-4, atol=1e-4)
    assert np.all(np.abs(np.asarray(action)) <= 2.0)


@pytest.mark.parametrize("direction", ["up", "down"])
def test_temperature_moves_towards_target_entropy(buffer, direction):
    # Entropy below the target -> the temperature grows; above it -> it shrinks.
    target = 50.0 if direction == "up" else -50.0
    cfg = SACConfig(**TINY, target_entropy=target, lr_temperature=1e-2)
    agent = make_sac(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    state, metrics = agent.update(agent.init(0), buffer.data, buffer.size, num_updates=10)
    temperature = float(metrics["temperature"])
    if direction == "up":
        assert temperature > 1.05
    else:
        assert temperature < 0.95
    # Each Adam step moves log(alpha) by about lr in the same direction.
    np.testing.assert_allclose(abs(float(state.log_temperature)), 10 * 1e-2, rtol=0.05)


def test_fixed_temperature(buffer):
    agent = make_sac(SACConfig(**TINY, autotune=False, init_temperature=0.2), OBS_DIM, ACT_DIM)
    _, metrics = agent.update(agent.init(0), buffer.data, buffer.size, num_updates=3)
    np.testing.assert_allclose(float(metrics["temperature"]), 0.2, rtol=1e-6)


def test_update_deterministic_and_scan_equals_single_steps(buffer):
    agent = make_sac(SACConfig(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    a, ma = agent.update(agent.init(1), buffer.data, buffer.size, num_updates=3)
    b, mb = agent.update(agent.init(1), buffer.data, buffer.size, num_updates=3)
    assert leaves_equal(a, b) and leaves_equal(ma, mb)
    s = agent.init(1)
    for _ in range(3):
        s, _ = agent.update(s, buffer.data, buffer.size, num_updates=1)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(s), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-6)
    assert int(a.step) == 3


def test_reward_scale_equals_scaled_rewards(buffer):
    scaled = make_sac(SACConfig(**TINY, reward_scale=4.0), OBS_DIM, ACT_DIM, MAX_ACTION)
    plain = make_sac(SACConfig(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    data4 = buffer.data._replace(reward=4.0 * buffer.data.reward)
    a, _ = scaled.update(scaled.init(0), buffer.data, buffer.size, num_updates=3)
    b, _ = plain.update(plain.init(0), data4, buffer.size, num_updates=3)
    c, _ = plain.update(plain.init(0), buffer.data, buffer.size, num_updates=3)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-6)
    assert not leaves_equal(a.critic_params, c.critic_params)
    with pytest.raises(ValueError, match="reward_scale"):
        SACConfig(reward_scale=0.0)


def test_target_is_polyak_average(buffer):
    cfg = SACConfig(**TINY, tau=0.1)
    agent = make_sac(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    s1, _ = agent.update(s0, buffer.data, buffer.size, num_updates=1)
    for n, o, t in zip(
        jax.tree.leaves(s1.critic_params),
        jax.tree.leaves(s0.critic_params),
        jax.tree.leaves(s1.critic_target),
        strict=True,
    ):
        np.testing.assert_allclose(
            np.asarray(t), 0.1 * np.asarray(n) + 0.9 * np.asarray(o), rtol=0, atol=1e-7
        )


def test_critic_loss_decreases():
    buf = random_buffer(seed=1, episodes=2, length=32)
    buf.data = buf.data._replace(not_done=jnp.zeros_like(buf.data.not_done))
    cfg = SACConfig(**TINY, lr_critic=3e-3, lr_actor=0.0)
    agent = make_sac(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    state, first = agent.update(agent.init(0), buf.data, buf.size, num_updates=10)
    state, _ = agent.update(state, buf.data, buf.size, num_updates=300)
    _, last = agent.update(state, buf.data, buf.size, num_updates=10)
    assert float(last["critic_loss"]) < 0.3 * float(first["critic_loss"])


def test_act(buffer):
    agent = make_sac(SACConfig(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    state = agent.init(0)
    obs = np.random.default_rng(0).normal(size=(32, OBS_DIM)).astype(np.float32)
    det = np.asarray(agent.act(state, obs))
    assert det.shape == (32, ACT_DIM) and np.all(np.abs(det) <= MAX_ACTION)
    np.testing.assert_array_equal(det, np.asarray(agent.act(state, obs)))
    sampled = np.asarray(agent.act(state, obs, jax.random.PRNGKey(0)))
    assert np.all(np.abs(sampled) <= MAX_ACTION) and not np.allclose(sampled, det)
    mean, std = np.full(OBS_DIM, 0.5), np.full(OBS_DIM, 2.0)
    normed = agent.set_normalizer(state, mean, std)
    np.testing.assert_allclose(
        np.asarray(agent.act(normed, obs)),
        np.asarray(agent.act(state, (obs - 0.5) / 2.0)),
        rtol=1e-5,
        atol=1e-6,
    )
    q = np.asarray(agent.q_values(normed, obs, det))
    assert q.shape == (2, 32) and not np.allclose(q[0], q[1])
    np.testing.assert_allclose(
        q, np.asarray(agent.q_values(state, (obs - 0.5) / 2.0, det)), rtol=1e-5, atol=1e-6
    )
    with pytest.raises(RuntimeError):
        agent.set_normalizer(normed, mean, std)
