"""TD7: SALE's pieces against hand computations, its schedules, and its update mechanics."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from agent_helpers import ACT_DIM, MAX_ACTION, OBS_DIM

from ilfo.agents.critic_targets import pal_loss
from ilfo.agents.td7 import (
    Encoder,
    TD7Config,
    avg_l1_norm,
    clip_target,
    encoder_loss,
    make_td7,
)
from ilfo.replay import sample_batch

SMALL = {
    "zs_dim": 8,
    "encoder_hidden": 16,
    "actor_hidden": 16,
    "critic_hidden": 16,
    "batch_size": 8,
    "time_augmentation": False,
}


def tree_equal(a, b) -> bool:
    return all(
        np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


def test_avg_l1_norm_by_hand():
    x = np.array([[1.0, -3.0, 2.0], [0.0, 0.0, 0.0]], np.float32)
    out = np.asarray(avg_l1_norm(x))
    np.testing.assert_allclose(out[0], x[0] / 2.0, rtol=1e-6)
    assert np.all(out[1] == 0.0)  # the floor keeps a zero row finite


def _elu(x):
    return np.where(x > 0, x, np.expm1(np.minimum(x, 0)))


def test_encoder_loss_by_hand():
    encoder = Encoder(OBS_DIM, ACT_DIM, zs_dim=5, hidden=7)
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(6, OBS_DIM)).astype(np.float32)
    next_obs = rng.normal(size=(6, OBS_DIM)).astype(np.float32)
    action = rng.uniform(-1, 1, size=(6, ACT_DIM)).astype(np.float32)
    params = encoder.init(jax.random.PRNGKey(0), obs, action)
    p = jax.tree.map(np.asarray, params["params"])

    def layer(name, x):
        return x @ p[name]["kernel"] + p[name]["bias"]

    def zs(s):
        h = _elu(layer("zs_layers_1", _elu(layer("zs_layers_0", s))))
        z = layer("zs_layers_2", h)
        return z / np.abs(z).mean(-1, keepdims=True)

    def zsa(z, a):
        h = _elu(layer("zsa_layers_0", np.concatenate([z, a], -1)))
        return layer("zsa_layers_2", _elu(layer("zsa_layers_1", h)))

    expected = np.mean((zsa(zs(obs), action) - zs(next_obs)) ** 2)
    got = float(encoder_loss(encoder, params, obs, action, next_obs))
    np.testing.assert_allclose(got, expected, rtol=1e-5)
    # The target side is a constant: the gradient flows through zs(s) and zsa only.
    grad_next = jax.grad(lambda n: encoder_loss(encoder, params, obs, action, n))(next_obs)
    assert not np.any(np.asarray(grad_next))


def test_clip_target():
    values = np.array([-5.0, 0.5, 9.0], np.float32)
    bounds = np.array([-1.0, 2.0], np.float32)
    np.testing.assert_array_equal(np.asarray(clip_target(values, bounds, True)), [-1.0, 0.5, 2.0])
    np.testing.assert_array_equal(np.asarray(clip_target(values, bounds, False)), values)


def test_first_critic_loss_is_pal_of_q_minus_reward(buffer):
    # Before the first target update the clipping range is [0, 0]: every bootstrapped value is
    # clipped to 0, so the first update's TD target is the reward alone.
    agent = make_td7(TD7Config(**SMALL), OBS_DIM, ACT_DIM, MAX_ACTION)
    state = agent.init(0)
    _, k_batch, _ = jax.random.split(state.key, 3)
    batch = sample_batch(buffer.data, buffer.size, k_batch, SMALL["batch_size"])
    q = agent.q_values(state, batch.obs, batch.action)
    expected = float(pal_loss(q - batch.reward))
    _, metrics = agent.update(state, buffer.data, buffer.size, num_updates=1)
    np.testing.assert_allclose(float(metrics["critic_loss"]), expected, rtol=1e-5)


def test_hard_target_updates_and_the_fixed_encoder(buffer):
    every = 3
    agent = make_td7(TD7Config(**SMALL, target_update_every=every), OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(1)
    s2, _ = agent.update(s0, buffer.data, buffer.size, num_updates=every - 1)
    # Between target updates: targets and the fixed encoder stay; the trained encoder moves.
    assert tree_equal(s2.actor_params["encoder"], s0.actor_params["encoder"])
    assert tree_equal(s2.actor_target, s0.actor_target)
    assert tree_equal(s2.critic_target, s0.critic_target)
    assert not tree_equal(s2.encoder_params, s0.encoder_params)
    assert np.array_equal(np.asarray(s2.target_range), [0.0, 0.0])
    s3, _ = agent.update(s2, buffer.data, buffer.size, num_updates=1)
    assert tree_equal(s3.actor_params["encoder"], s3.encoder_params)
    assert tree_equal(s3.actor_target["encoder"], s2.actor_params["encoder"])
    assert tree_equal(s3.actor_target["actor"], s3.actor_params["actor"])
    assert tree_equal(s3.critic_target, s3.critic_params)
    low, high = np.asarray(s3.target_range)
    assert low <= high and np.array_equal(np.asarray(s3.target_range), np.asarray(s3.seen_range))


def test_policy_delay(buffer):
    agent = make_td7(TD7Config(**SMALL, policy_delay=2), OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    s1, _ = agent.update(s0, buffer.data, buffer.size, num_updates=1)
    assert tree_equal(s1.actor_params["actor"], s0.actor_params["actor"])
    assert not tree_equal(s1.critic_params, s0.critic_params)
    s2, _ = agent.update(s1, buffer.data, buffer.size, num_updates=1)
    assert not tree_equal(s2.actor_params["actor"], s1.actor_params["actor"])


@pytest.mark.parametrize("time_augmentation", [False, True])
def test_same_seed_same_numbers_and_scan_equals_single_steps(buffer, time_augmentation):
    cfg = TD7Config(**{**SMALL, "time_augmentation": time_augmentation}, target_update_every=2)
    agent = make_td7(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    a, ma = agent.update(agent.init(3), buffer.data, buffer.size, num_updates=4)
    b, mb = agent.update(agent.init(3), buffer.data, buffer.size, num_updates=4)
    assert tree_equal(a, b) and tree_equal(ma, mb)
    s = agent.init(3)
    for _ in range(4):
        s, _ = agent.update(s, buffer.data, buffer.size, num_updates=1)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(s), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-6)
    c, _ = agent.update(agent.init(4), buffer.data, buffer.size, num_updates=4)
    assert not tree_equal(a.actor_params, c.actor_params)


def test_act_bounds_and_policy_acts_as_the_state(buffer):
    from ilfo.agents import policy_of

    agent = make_td7(TD7Config(**SMALL), OBS_DIM, ACT_DIM, MAX_ACTION)
    state, _ = agent.update(agent.init(0), buffer.data, buffer.size, num_updates=2)
    obs = np.asarray(buffer.data.obs[:5])
    greedy = np.asarray(agent.act(state, obs))
    assert np.array_equal(greedy, np.asarray(agent.act(policy_of(state), obs)))
    noisy = np.asarray(agent.act(state, obs, jax.random.PRNGKey(0)))
    assert np.all(np.abs(noisy) <= MAX_ACTION) and not np.array_equal(noisy, greedy)


@pytest.mark.parametrize(
    "bad",
    [
        {"zs_dim": 0},
        {"target_update_every": 0},
        {"lr_encoder": -1e-3},
        {"gamma": 1.5},
        {"time_augmentation_scheme": "next_only"},
        {"target_noise": -0.1},
    ],
)
def test_bad_settings_are_refused(bad):
    with pytest.raises(ValueError):
        TD7Config(**bad)


def test_fast_preset_is_smaller_and_otherwise_the_authors():
    authors, fast = TD7Config(), TD7Config.fast()
    assert fast.batch_size < authors.batch_size and fast.critic_hidden < authors.critic_hidden
    for field in ("gamma", "target_update_every", "policy_delay", "pal_alpha", "lr_critic"):
        assert getattr(fast, field) == getattr(authors, field), field
