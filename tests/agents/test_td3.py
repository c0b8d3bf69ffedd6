"""Tests of TD3 (ilfo.agents.td3): PAL loss, targets, time augmentation, determinism."""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from agent_helpers import ACT_DIM, MAX_ACTION, OBS_DIM, TINY, random_buffer

from ilfo.agents import TD3Config, critic_loss, ddpg_config, make_td3, pal_loss, policy_of
from ilfo.agents.critic_targets import augment_time, redraw_next_time


def tree_allclose(a, b, **kw) -> bool:
    return all(
        np.allclose(np.asarray(x), np.asarray(y), **kw)
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


def tree_equal(a, b) -> bool:
    return all(
        np.array_equal(np.asarray(x), np.asarray(y))
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


# --- PAL loss -------------------------------------------------------------------------------


def test_pal_loss_by_hand():
    td = [[0.5, -2.0, 3.0], [0.1, 1.5, -0.2]]  # (2 critics, batch 3)
    a = 0.4

    def f(x: float) -> float:  # min priority 1
        return 0.5 * x * x if abs(x) < 1 else abs(x) ** (1 + a) / (1 + a)

    # Per-sample priorities use the larger |td| of the two critics, floored at 1.
    normaliser = (1.0 + 2.0**a + 3.0**a) / 3
    expected = sum(sum(f(x) for x in row) / 3 for row in td) / normaliser
    got = float(pal_loss(jnp.array(td), alpha=a, min_priority=1.0))
    assert math.isclose(got, expected, rel_tol=1e-6)
    # The same numbers written out by hand:
    # critic 1: f(0.5) = 0.125, f(-2) = 2^1.4 / 1.4 = 1.885011, f(3) = 3^1.4 / 1.4 = 3.325383
    # critic 2: f(0.1) = 0.005, f(1.5) = 1.5^1.4 / 1.4 = 1.260085, f(-0.2) = 0.02
    # normaliser: mean(1, 2^0.4, 3^0.4) = (1 + 1.319508 + 1.551846) / 3 = 1.290451
    by_hand = ((0.125 + 1.885011 + 3.325383) / 3 + (0.005 + 1.260085 + 0.02) / 3) / 1.290451
    assert math.isclose(got, by_hand, rel_tol=1e-5)
    assert math.isclose(got, 1.7101201, rel_tol=1e-6)


def test_pal_loss_general_min_priority_and_gradient():
    m, a = 2.0, 0.4
    td = jnp.array([[0.5, -3.0, 2.5, 1.0]])
    per = [m**a * 0.5 * 0.25, m * 3.0 ** (1 + a) / (1 + a), m * 2.5 ** (1 + a) / (1 + a)]
    per.append(m**a * 0.5 * 1.0)
    normaliser = np.mean([m**a, 3.0**a, 2.5**a, m**a])
    assert math.isclose(float(pal_loss(td, a, m)), np.mean(per) / normaliser, rel_tol=1e-6)

    # The normaliser is a constant for the gradient: d/dx = f'(x) / (B * normaliser), where
    # f'(x) = m^a x below m and m |x|^a sign(x) above: continuous at |x| = m.
    grad = np.asarray(jax.grad(lambda x: pal_loss(x, a, m))(td))[0]
    fprime = np.array([m**a * 0.5, -m * 3.0**a, m * 2.5**a, m**a * 1.0])
    np.testing.assert_allclose(grad, fprime / (4 * normaliser), rtol=1e-6)
    grad_at = jax.grad(lambda x: pal_loss(x, a, m))
    below, above = grad_at(jnp.array([[m - 1e-4]])), grad_at(jnp.array([[m + 1e-4]]))
    assert math.isclose(float(below[0, 0]), float(above[0, 0]), rel_tol=1e-3)


def test_other_critic_losses():
    td = jnp.array([[0.5, -2.0], [1.0, 0.0]])
    assert math.isclose(float(critic_loss(td, "mse")), (0.25 + 4.0) / 2 + 1.0 / 2)
    huber = (0.125 + 1.5) / 2 + 0.5 / 2
    assert math.isclose(float(critic_loss(td, "huber")), huber)
    with pytest.raises(ValueError):
        TD3Config(loss="l1")


# --- configs --------------------------------------------------------------------------------


def test_fast_is_the_paper_preset_with_narrower_critics():
    paper, fast = TD3Config.paper(), TD3Config.fast()
    assert max(fast.critic_hidden) < max(paper.critic_hidden)
    assert dataclasses.replace(fast, critic_hidden=paper.critic_hidden) == paper
    assert TD3Config.fast(batch_size=32) == dataclasses.replace(fast, batch_size=32)
    with pytest.raises(dataclasses.FrozenInstanceError):
        paper.tau = 0.1  # type: ignore[misc]


def test_ddpg_config_drops_td3s_three_ingredients_and_keeps_the_rest(buffer):
    base = TD3Config.fast(**TINY)
    ddpg = ddpg_config(base)
    assert ddpg_config() == ddpg_config(TD3Config.paper())
    kept = {f: getattr(base, f) for f in ("num_critics", "target_noise", "noise_clip")}
    assert dataclasses.replace(ddpg, **kept, policy_delay=base.policy_delay) == base
    assert ddpg.target_noise == 0.0  # no target policy smoothing
    agent = make_td3(ddpg, OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    obs, action = buffer.data.obs[:5], buffer.data.action[:5]
    assert agent.q_values(s0, obs, action).shape[0] == 1  # one critic: no clipped double Q
    s1, _ = agent.update(s0, buffer.data, buffer.size, num_updates=1)
    assert not tree_equal(s1.actor_params, s0.actor_params)  # the actor learns every update


# --- update mechanics -----------------------------------------------------------------------


def test_polyak_targets_exact(buffer):
    cfg = TD3Config(**TINY, policy_delay=1, tau=0.25)
    agent = make_td3(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    s1, _ = agent.update(s0, buffer.data, buffer.size, num_updates=1)
    # At init target == online, so after one step target = tau * new + (1 - tau) * old.
    for new, old, tgt in (
        (s1.critic_params, s0.critic_params, s1.critic_target),
        (s1.actor_params, s0.actor_params, s1.actor_target),
    ):
        expected = jax.tree.map(lambda n, o: 0.25 * np.asarray(n) + 0.75 * np.asarray(o), new, old)
        assert tree_allclose(tgt, expected, rtol=0, atol=1e-7)
        assert not tree_allclose(new, old)


def test_policy_delay(buffer):
    agent = make_td3(TD3Config(**TINY, policy_delay=2), OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    s1, _ = agent.update(s0, buffer.data, buffer.size, num_updates=1)
    assert not tree_equal(s1.critic_params, s0.critic_params)
    for name in ("actor_params", "actor_target", "critic_target"):
        assert tree_equal(getattr(s1, name), getattr(s0, name)), name
    s2, _ = agent.update(s1, buffer.data, buffer.size, num_updates=1)
    for name in ("actor_params", "actor_target", "critic_target"):
        assert not tree_equal(getattr(s2, name), getattr(s1, name)), name
    assert int(s2.step) == 2


def test_update_deterministic_and_scan_equals_single_steps(buffer):
    agent = make_td3(TD3Config.fast(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(3)
    a, ma = agent.update(s0, buffer.data, buffer.size, num_updates=4)
    b, mb = agent.update(agent.init(3), buffer.data, buffer.size, num_updates=4)
    assert tree_equal(a, b) and tree_equal(ma, mb)

    s = s0
    for _ in range(4):
        s, _ = agent.update(s, buffer.data, buffer.size, num_updates=1)
    assert tree_allclose(a, s, rtol=1e-5, atol=1e-6)
    assert int(a.step) == 4
    c, _ = agent.update(agent.init(4), buffer.data, buffer.size, num_updates=4)
    assert not tree_allclose(a.actor_params, c.actor_params)


def test_grouped_updates_equal_one_by_one_aligned_or_not(buffer):
    # With policy_delay 2, an even number of updates from an even step runs as groups (critic
    # update, then critic + actor) with no run-time cond; from an odd step, one by one.
    agent = make_td3(TD3Config.fast(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    for first in (0, 1):
        s = agent.init(5)
        if first:
            s, _ = agent.update(s, buffer.data, buffer.size, num_updates=first)
        grouped, m_grouped = agent.update(s, buffer.data, buffer.size, num_updates=6)
        singles, actor_losses = s, []
        for _ in range(6):
            singles, m = agent.update(singles, buffer.data, buffer.size, num_updates=1)
            if int(singles.step) % 2 == 0:
                actor_losses.append(float(m["actor_loss"]))
        assert int(grouped.step) == first + 6
        assert tree_allclose(grouped, singles, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(float(m_grouped["actor_loss"]), np.mean(actor_losses), 1e-5)


@pytest.mark.parametrize("loss", ["pal", "mse", "huber"])
def test_critic_loss_decreases(loss):
    # Terminal transitions: the critics regress on a fixed reward r(s, a).
    buf = random_buffer(seed=1, episodes=2, length=32)
    buf.data = buf.data._replace(not_done=jnp.zeros_like(buf.data.not_done))
    cfg = TD3Config(**TINY, loss=loss, lr_critic=3e-3, lr_actor=0.0)
    agent = make_td3(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    state = agent.init(0)
    state, first = agent.update(state, buf.data, buf.size, num_updates=10)
    state, _ = agent.update(state, buf.data, buf.size, num_updates=300)
    _, last = agent.update(state, buf.data, buf.size, num_updates=10)
    assert float(last["critic_loss"]) < 0.3 * float(first["critic_loss"])


def test_update_only_reads_filled_slots(buffer):
    data = jax.tree.map(lambda x: x.at[buffer.size :].set(jnp.nan), buffer.data)
    agent = make_td3(TD3Config(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    state, metrics = agent.update(agent.init(0), data, buffer.size, num_updates=20)
    assert all(np.isfinite(float(v)) for v in metrics.values())
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(state))


def test_ddpg_runs(buffer):
    agent = make_td3(ddpg_config(TD3Config(**TINY)), OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    assert jax.tree.leaves(s0.critic_params)[0].shape[0] == 1
    s1, m = agent.update(s0, buffer.data, buffer.size, num_updates=3)
    assert not tree_equal(s1.actor_params, s0.actor_params)
    assert np.isfinite(float(m["actor_loss"]))


# --- time augmentation ----------------------------------------------------------------------


def test_augment_time_draws_one_time_to_go_per_row():
    obs = jax.random.normal(jax.random.PRNGKey(0), (5000, 4))
    next_obs = jax.random.normal(jax.random.PRNGKey(2), (5000, 4))
    o, n, not_done = augment_time(jax.random.PRNGKey(1), obs, next_obs, max_time=1000)
    np.testing.assert_array_equal(np.asarray(o[:, :-1]), np.asarray(obs[:, :-1]))
    np.testing.assert_array_equal(np.asarray(n[:, :-1]), np.asarray(next_obs[:, :-1]))
    k = np.asarray(o[:, -1]) * 1000
    np.testing.assert_allclose(k, np.round(k), atol=1e-3)
    assert k.min() >= 1 - 1e-3 and k.max() <= 1000 + 1e-3
    assert len(np.unique(np.round(k))) > 900  # uniform over {1..1000}: draws vary per row
    # The next state is one step closer to the horizon; the episode ends exactly at k = 1.
    np.testing.assert_allclose(np.asarray(n[:, -1]) * 1000, k - 1, atol=1e-3)
    np.testing.assert_array_equal(np.asarray(not_done), (np.round(k) > 1).astype(np.float32))


def test_time_augmentation_critic_ignores_recorded_times_and_ends():
    buf = random_buffer(seed=2)
    cfg = TD3Config(**TINY, time_augmentation=True)
    agent = make_td3(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    # One update trains the critic only (policy delay 2): its inputs' times are all drawn, and
    # its bootstrapping is cut by the draw, so the recorded times and ends change nothing.
    base, _ = agent.update(s0, buf.data, buf.size, num_updates=1)
    other = buf.data._replace(
        obs=buf.data.obs.at[:, -1].set(0.777),
        next_obs=buf.data.next_obs.at[:, -1].set(0.123),
        not_done=1.0 - buf.data.not_done,
    )
    same, _ = agent.update(s0, other, buf.size, num_updates=1)
    assert tree_equal(base.critic_params, same.critic_params)
    # The actor loss uses the recorded time of s.
    a, _ = agent.update(s0, buf.data, buf.size, num_updates=2)
    b, _ = agent.update(s0, other, buf.size, num_updates=2)
    assert not tree_allclose(a.actor_params, b.actor_params)
    # Without augmentation the recorded time of s' matters.
    plain = make_td3(TD3Config(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    p0 = plain.init(0)
    a, _ = plain.update(p0, buf.data, buf.size, num_updates=4)
    b, _ = plain.update(p0, buf.data._replace(next_obs=other.next_obs), buf.size, num_updates=4)
    assert not tree_allclose(a.critic_params, b.critic_params)


def test_time_augmentation_is_the_recorded_backup_at_the_drawn_time():
    # With a horizon of 1 the draw is always k = 1: current time 1, next time 0, no bootstrap.
    # That must be exactly the plain update on data recorded that way.
    buf = random_buffer(seed=3)
    aug = make_td3(
        TD3Config(**TINY, time_augmentation=True, max_time=1), OBS_DIM, ACT_DIM, MAX_ACTION
    )
    plain = make_td3(TD3Config(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    recorded = buf.data._replace(
        obs=buf.data.obs.at[:, -1].set(1.0),
        next_obs=buf.data.next_obs.at[:, -1].set(0.0),
        not_done=jnp.zeros_like(buf.data.not_done),
    )
    a, _ = aug.update(aug.init(0), recorded, buf.size, num_updates=3)
    b, _ = plain.update(plain.init(0), recorded, buf.size, num_updates=3)
    assert tree_allclose(a.critic_params, b.critic_params, atol=1e-6)
    assert tree_allclose(a.actor_params, b.actor_params, atol=1e-6)
    # ... and differs from the plain update that bootstraps (not_done = 1).
    c, _ = plain.update(
        plain.init(0), recorded._replace(not_done=jnp.ones_like(recorded.not_done)), buf.size, 3
    )
    assert not tree_allclose(a.critic_params, c.critic_params, atol=1e-6)


def test_redraw_next_time_changes_only_the_next_time():
    next_obs = jax.random.normal(jax.random.PRNGKey(2), (5000, 4))
    n = redraw_next_time(jax.random.PRNGKey(1), next_obs, max_time=1000)
    np.testing.assert_array_equal(np.asarray(n[:, :-1]), np.asarray(next_obs[:, :-1]))
    k = np.asarray(n[:, -1]) * 1000
    np.testing.assert_allclose(k, np.round(k), atol=1e-3)
    assert k.min() >= 1 - 1e-3 and k.max() <= 1000 + 1e-3
    assert len(np.unique(np.round(k))) > 900


def test_next_only_scheme_keeps_recorded_time_and_ends():
    buf = random_buffer(seed=4)
    cfg = TD3Config(**TINY, time_augmentation=True, time_augmentation_scheme="next_only")
    agent = make_td3(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    s0 = agent.init(0)
    base, _ = agent.update(s0, buf.data, buf.size, num_updates=1)
    # The recorded next time is redrawn: changing it changes nothing ...
    moved_next = buf.data._replace(next_obs=buf.data.next_obs.at[:, -1].set(0.123))
    same, _ = agent.update(s0, moved_next, buf.size, num_updates=1)
    assert tree_equal(base.critic_params, same.critic_params)
    # ... but the critic is trained at the recorded current time and ends.
    moved_now = buf.data._replace(obs=buf.data.obs.at[:, -1].set(0.777))
    a, _ = agent.update(s0, moved_now, buf.size, num_updates=1)
    assert not tree_allclose(base.critic_params, a.critic_params)
    ends = buf.data._replace(not_done=1.0 - buf.data.not_done)
    b, _ = agent.update(s0, ends, buf.size, num_updates=1)
    assert not tree_allclose(base.critic_params, b.critic_params)
    # With a horizon of 1 the redrawn next time is always 1: the plain update on such data.
    one = make_td3(
        TD3Config(**TINY, time_augmentation=True, time_augmentation_scheme="next_only", max_time=1),
        OBS_DIM,
        ACT_DIM,
        MAX_ACTION,
    )
    plain = make_td3(TD3Config(**TINY), OBS_DIM, ACT_DIM, MAX_ACTION)
    recorded = buf.data._replace(next_obs=buf.data.next_obs.at[:, -1].set(1.0))
    c, _ = one.update(one.init(0), buf.data, buf.size, num_updates=3)
    d, _ = plain.update(plain.init(0), recorded, buf.size, num_updates=3)
    assert tree_allclose(c.critic_params, d.critic_params, atol=1e-6)
    assert tree_allclose(c.actor_params, d.actor_params, atol=1e-6)
    with pytest.raises(ValueError, match="time_augmentation_scheme"):
        TD3Config(**TINY, time_augmentation_scheme="both")


# --- acting and the normaliser --------------------------------------------------------------


def test_act_and_normaliser():
    cfg = TD3Config(**TINY, time_augmentation=True)
    agent = make_td3(cfg, OBS_DIM, ACT_DIM, MAX_ACTION)
    state = agent.init(0)
    obs = np.random.default_rng(0).normal(size=(64, OBS_DIM)).astype(np.float32)
    a = np.asarray(agent.act(state, obs))
    assert a.shape == (64, ACT_DIM) and np.all(np.abs(a) <= MAX_ACTION)
    assert agent.act(state, obs[0]).shape == (ACT_DIM,)
    noisy = np.asarray(agent.act(state, obs, jax.random.PRNGKey(0)))
    assert np.all(np.abs(noisy) <= MAX_ACTION) and not np.allclose(noisy, a)
    assert np.abs(noisy - a).mean() < 2 * cfg.exploration_noise * MAX_ACTION

    mean, std = np.array([1.0, -2.0, 0.5]), np.array([2.0, 0.5, 3.0])  # time feature left out
    normed = agent.set_normalizer(state, mean, std)
    np.testing.assert_array_equal(np.asarray(normed.obs_mean), [1.0, -2.0, 0.5, 0.0])
    np.testing.assert_array_equal(np.asarray(normed.obs_std), [2.0, 0.5, 3.0, 1.0])
    full_mean, full_std = np.append(mean, 0.0), np.append(std, 1.0)
    np.testing.assert_allclose(
        np.asarray(agent.act(normed, obs)),
        np.asarray(agent.act(state, (obs - full_mean) / full_std)),
        rtol=1e-5,
        atol=1e-6,
    )
    with pytest.raises(RuntimeError):
        agent.set_normalizer(normed, mean, std)
    with pytest.raises(ValueError):
        agent.set_normalizer(state, mean, np.zeros(3))

    # The critics' values see the same normalised observations; each critic is its own.
    action = np.asarray(agent.act(state, obs))
    q = np.asarray(agent.q_values(normed, obs, action))
    assert q.shape == (cfg.num_critics, 64) and not np.allclose(q[0], q[1])
    np.testing.assert_allclose(
        q, np.asarray(agent.q_values(state, (obs - full_mean) / full_std, action)), rtol=1e-5
    )


def test_policy_acts_as_the_state_and_serialises_as_policy_files_do():
    import flax.serialization

    agent = make_td3(TD3Config(**TINY, time_augmentation=True), OBS_DIM, ACT_DIM, MAX_ACTION)
    state = agent.set_normalizer(agent.init(0), np.array([1.0, -2.0, 0.5]), np.full(3, 2.0))
    policy = policy_of(state)
    obs = np.random.default_rng(1).normal(size=(8, OBS_DIM)).astype(np.float32)
    key = jax.random.PRNGKey(3)
    np.testing.assert_array_equal(agent.act(policy, obs), agent.act(state, obs))
    np.testing.assert_array_equal(agent.act(policy, obs, key), agent.act(state, obs, key))
    # Policy files: the keys actor_params, obs_mean, obs_std (as the shipped experts' files).
    blob = flax.serialization.to_bytes(policy)
    assert set(flax.serialization.msgpack_restore(blob)) == {"actor_params", "obs_mean", "obs_std"}
    restored = flax.serialization.from_bytes(policy_of(agent.init(1)), blob)
    np.testing.assert_array_equal(agent.act(restored, obs), agent.act(state, obs))


def test_max_action_must_be_shared():
    with pytest.raises(ValueError):
        make_td3(TD3Config(**TINY), OBS_DIM, ACT_DIM, np.array([1.0, 2.0]))
    agent = make_td3(TD3Config(**TINY), OBS_DIM, ACT_DIM, np.array([2.0, 2.0]))
    assert agent.max_action == 2.0
