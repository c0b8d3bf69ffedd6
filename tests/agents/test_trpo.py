"""Tests of TRPO (ilfo.agents.trpo): GAE, the Fisher, the trust region, learning."""

from __future__ import annotations

import math

import flax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree
from scipy.stats import norm

from ilfo.agents._common import Policy, policy_of
from ilfo.agents.trpo import (
    GaussianMLPPolicy,
    OnPolicyBatch,
    TRPOConfig,
    conjugate_gradients,
    fisher_vector_product,
    gae,
    make_trpo,
)

OBS_DIM, ACT_DIM = 2, 2
HIDDEN = (16, 16)
N = 512
# The bandit's best action is W s (reward -|a - W s|^2, one step per episode).
W = np.array([[1.0, -0.5], [0.3, 0.8]])


def small_agent(**overrides):
    return make_trpo(TRPOConfig(hidden=HIDDEN, **overrides), OBS_DIM, ACT_DIM, max_action=1.0)


def bandit_batch(agent, state, key, seed=0, n=N, episode_length=1) -> OnPolicyBatch:
    obs = np.random.default_rng(seed).normal(size=(n, OBS_DIM)).astype(np.float32)
    action = np.asarray(agent.act(state, obs, key))
    reward = -np.sum((action - obs @ W.T) ** 2, axis=1)
    end = np.arange(n) % episode_length == episode_length - 1
    return OnPolicyBatch(obs, action, reward, end)


def log_std_of(state) -> np.ndarray:
    return np.asarray(state.actor_params["params"]["log_std"], np.float64)


def measured_kl(agent, old, new, obs) -> float:
    """Mean over obs of KL(pi_old || pi_new), in float64 from the two policies' outputs."""
    m0 = np.asarray(agent.act(old, obs), np.float64)
    m1 = np.asarray(agent.act(new, obs), np.float64)
    s0, s1 = np.exp(log_std_of(old)), np.exp(log_std_of(new))
    kl = np.log(s1 / s0) + (s0**2 + (m0 - m1) ** 2) / (2 * s1**2) - 0.5
    return float(np.mean(np.sum(kl, axis=-1)))


def leaves_equal(a, b) -> bool:
    return all(
        np.array_equal(np.asarray(x), np.asarray(y))
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


def test_defaults_follow_sil_code():
    c = TRPOConfig()
    assert c.hidden == (128, 128) and c.log_std_init == 0.0
    assert (c.max_kl, c.damping, c.cg_iters, c.line_search_steps, c.accept_ratio) == (
        0.1,
        0.1,
        10,
        10,
        0.1,
    )
    assert (c.gamma, c.gae_lambda, c.value_l2, c.value_iters) == (0.99, 0.97, 1e-3, 25)
    assert (c.batch_steps, c.obs_clip) == (50_000, 5.0)
    assert c.kl_check  # ilfo's departure: SIL's code has no KL check
    assert make_trpo(c, 3, 1, 2.0).batch_steps == 50_000


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("hidden", ()),
        ("hidden", (16, 0)),
        ("max_kl", 0.0),
        ("max_kl", math.nan),
        ("damping", -0.1),
        ("cg_iters", 0),
        ("line_search_steps", 0),
        ("accept_ratio", 0.0),
        ("gamma", 0.0),
        ("gamma", 1.01),
        ("gae_lambda", 1.5),
        ("value_l2", -1.0),
        ("value_iters", 0),
        ("batch_steps", 0),
        ("batch_steps", 10.5),
        ("obs_clip", 0.0),
        ("log_std_init", math.inf),
    ],
)
def test_config_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=field):
        TRPOConfig(**{field: value})


def test_make_rejects_bad_sizes():
    with pytest.raises(ValueError, match="obs_dim"):
        make_trpo(TRPOConfig(), 0, 1, 1.0)
    with pytest.raises(ValueError, match="max_action"):
        make_trpo(TRPOConfig(), 3, 1, 0.0)


def test_gae_by_hand_two_episodes():
    r = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    v = np.array([0.5, 0.6, 0.7, 0.8, 0.9])
    end = np.array([False, False, True, False, True])
    g, lam = 0.9, 0.8
    # Episode 1 (steps 0-2): its last step is not bootstrapped (V of step 3 belongs to episode 2).
    d2 = 3.0 - 0.7
    d1 = 2.0 + g * 0.7 - 0.6
    d0 = 1.0 + g * 0.6 - 0.5
    a2 = d2
    a1 = d1 + g * lam * a2
    a0 = d0 + g * lam * a1
    # Episode 2 (steps 3-4).
    a4 = 5.0 - 0.9
    a3 = 4.0 + g * 0.9 - 0.8 + g * lam * a4
    np.testing.assert_allclose(gae(r, v, end, g, lam), [a0, a1, a2, a3, a4], rtol=1e-12)
    # lambda = 1: discounted returns minus values; lambda = 0: one-step TD errors.
    np.testing.assert_allclose(
        gae(r, v, end, g, 1.0),
        [1 + g * 2 + g**2 * 3 - 0.5, 2 + g * 3 - 0.6, 3 - 0.7, 4 + g * 5 - 0.8, 5 - 0.9],
        rtol=1e-12,
    )
    np.testing.assert_allclose(gae(r, v, end, g, 0.0), [d0, d1, d2, a3 - g * lam * a4, a4])
    with pytest.raises(ValueError, match="episode end"):
        gae(r, v, np.array([False, False, True, False, False]), g, lam)


def test_init_follows_spec():
    agent = small_agent(log_std_init=-0.5)
    state = agent.init(0)
    for net in (state.actor_params["params"]["mean"], state.value_params["params"]["value"]):
        fan_ins = (OBS_DIM, HIDDEN[0], HIDDEN[1])
        for i, fan_in in enumerate(fan_ins):
            layer = net[f"Dense_{i}"]
            bound = (0.1 if i == 2 else 1.0) / math.sqrt(fan_in)  # the head: PyTorch's x 0.1
            kernel = np.abs(np.asarray(layer["kernel"]))
            assert kernel.max() <= bound and kernel.max() > 0.5 * bound
            bias = np.abs(np.asarray(layer["bias"]))
            if i == 2:
                assert np.all(bias == 0)
            else:
                assert bias.max() <= bound and bias.max() > 0
    np.testing.assert_array_equal(log_std_of(state), [-0.5, -0.5])
    assert int(state.iterations) == 0 and not bool(state.normalizer_set)
    assert leaves_equal(state, agent.init(0))
    assert not leaves_equal(state.actor_params, agent.init(1).actor_params)


def test_state_and_policy_serialize():
    agent = small_agent()
    state = agent.set_normalizer(agent.init(0), [0.5, -1.0], [2.0, 0.5])
    template = agent.init(1)
    restored = flax.serialization.from_bytes(template, flax.serialization.to_bytes(state))
    assert leaves_equal(restored, state) and bool(restored.normalizer_set)
    policy = flax.serialization.to_state_dict(policy_of(state))
    assert set(policy) == {"actor_params", "obs_mean", "obs_std"}
    assert set(policy["actor_params"]["params"]) == {"mean", "log_std"}


def test_act_log_prob_and_normalizer():
    agent = small_agent(log_std_init=-0.7, obs_clip=2.0)
    state = agent.set_normalizer(agent.init(0), [0.5, -1.0], [2.0, 0.5])
    policy = GaussianMLPPolicy(HIDDEN, ACT_DIM)
    obs = np.random.default_rng(0).normal(size=(64, OBS_DIM)).astype(np.float32)
    obs[0] = [100.0, -100.0]  # normalised beyond +-obs_clip: clipped
    seen = np.clip((obs - [0.5, -1.0]) / [2.0, 0.5], -2.0, 2.0)
    mean = np.asarray(policy.apply(state.actor_params, jnp.asarray(seen, jnp.float32))[0])
    np.testing.assert_allclose(np.asarray(agent.act(state, obs)), mean, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(
        np.asarray(agent.act(state, obs[:1])),
        np.asarray(agent.act(state, np.array([[0.5 + 2 * 2.0, -1.0 - 2 * 0.5]]))),
        rtol=1e-6,
    )
    # A Policy acts as the state does (the loop and policy files use one).
    pol = policy_of(state)
    assert isinstance(pol, Policy)
    key = jax.random.PRNGKey(3)
    np.testing.assert_array_equal(
        np.asarray(agent.act(pol, obs)), np.asarray(agent.act(state, obs))
    )
    np.testing.assert_array_equal(
        np.asarray(agent.act(pol, obs, key)), np.asarray(agent.act(state, obs, key))
    )
    # Samples: N(mean, exp(-0.7)^2), unclipped (max_action is 1).
    many = np.repeat(obs[1:2], 20_000, axis=0)
    samples = np.asarray(agent.act(state, many, key))
    np.testing.assert_allclose(samples.mean(0), mean[1], atol=0.02)
    np.testing.assert_allclose(samples.std(0), math.exp(-0.7), rtol=0.03)
    assert np.abs(samples).max() > 1.0
    # log_prob: the summed Gaussian log density.
    logp = np.asarray(agent.log_prob(pol, obs, samples[: len(obs)]))
    expected = norm.logpdf(samples[: len(obs)], mean, math.exp(-0.7)).sum(-1)
    np.testing.assert_allclose(logp, expected, rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(logp, np.asarray(agent.log_prob(state, obs, samples[: len(obs)])))
    with pytest.raises(RuntimeError):
        agent.set_normalizer(state, [0.0, 0.0], [1.0, 1.0])


def test_fisher_vector_product_is_the_analytic_fisher():
    policy = GaussianMLPPolicy((5,), 2)
    params = policy.init(jax.random.PRNGKey(0), jnp.zeros((1, 3)))
    log_std = jnp.array([-0.5, 0.4])
    params = {"params": {**params["params"], "log_std": log_std}}
    obs = jax.random.normal(jax.random.PRNGKey(1), (7, 3))
    keys = iter(jax.random.split(jax.random.PRNGKey(2), 16))
    v = jax.tree.map(lambda x: jax.random.normal(next(keys), x.shape), params)
    damping = 0.1
    fv = jax.jit(lambda v: fisher_vector_product(policy, params, obs, damping)(v))(v)

    mean_params = params["params"]["mean"]
    flat, unravel = ravel_pytree(mean_params)

    def mean_of(f):
        return policy.apply({"params": {"mean": unravel(f), "log_std": log_std}}, obs)[0]

    jac = np.asarray(jax.jit(jax.jacobian(mean_of))(flat), np.float64)  # (N, action_dim, P)
    inv_var = np.exp(-2.0 * np.asarray(log_std, np.float64))
    fisher = np.einsum("nap,a,naq->pq", jac, inv_var, jac) / obs.shape[0]
    v_mean = np.asarray(ravel_pytree(v["params"]["mean"])[0], np.float64)
    np.testing.assert_allclose(
        np.asarray(ravel_pytree(fv["params"]["mean"])[0]),
        fisher @ v_mean + damping * v_mean,
        rtol=2e-4,
        atol=2e-5,
    )
    v_std = np.asarray(v["params"]["log_std"])
    np.testing.assert_allclose(
        np.asarray(fv["params"]["log_std"]), (2.0 + damping) * v_std, rtol=1e-5
    )
    # The authors' form: 2 v on the mean network's parameters too, the log std's unchanged.
    code = jax.jit(lambda v: fisher_vector_product(policy, params, obs, damping, True)(v))(v)
    np.testing.assert_allclose(
        np.asarray(ravel_pytree(code["params"]["mean"])[0]),
        fisher @ v_mean + (2.0 + damping) * v_mean,
        rtol=2e-4,
        atol=2e-5,
    )
    np.testing.assert_array_equal(code["params"]["log_std"], fv["params"]["log_std"])


def test_conjugate_gradients():
    a = np.random.default_rng(0).normal(size=(6, 6))
    spd = jnp.asarray(a @ a.T + 0.5 * np.eye(6), jnp.float32)
    b = jnp.arange(1.0, 7.0)
    x = conjugate_gradients(lambda p: spd @ p, b, iters=30)
    np.testing.assert_allclose(np.asarray(spd @ x), np.asarray(b), atol=1e-3)
    # Two iterations are not enough for 6 dimensions: the count is honoured.
    x2 = conjugate_gradients(lambda p: spd @ p, b, iters=2)
    assert np.abs(np.asarray(spd @ x2 - b)).max() > 1e-2
    # A right-hand side below the tolerance: x = 0, no division by zero.
    np.testing.assert_array_equal(
        np.asarray(conjugate_gradients(lambda p: spd @ p, jnp.zeros(6), 10)), np.zeros(6)
    )


def test_steps_keep_to_the_trust_region_and_improve_the_surrogate():
    agent = small_agent(max_kl=0.05)
    state = agent.init(0)
    key = jax.random.PRNGKey(0)
    accepted = 0
    for i in range(4):
        key, k = jax.random.split(key)
        batch = bandit_batch(agent, state, k, seed=i)
        new, m = agent.learn(state, batch)
        kl = measured_kl(agent, state, new, batch.obs)
        assert kl <= 0.05 * (1 + 1e-4)
        # The surrogate with the batch's normalised advantages (one-step episodes: A = r - V).
        adv = batch.reward - np.asarray(agent.value(state, batch.obs), np.float64)
        adv = (adv - adv.mean()) / adv.std(ddof=1)
        ratio = np.exp(
            np.asarray(agent.log_prob(new, batch.obs, batch.action), np.float64)
            - np.asarray(agent.log_prob(state, batch.obs, batch.action), np.float64)
        )
        improvement = float(np.mean(adv * ratio))  # L_old - L_new (L_old = -mean(adv) = 0)
        if m["step_fraction"] > 0:
            accepted += 1
            assert improvement > 0
            assert m["step_fraction"] in [0.5**k for k in range(10)]
            np.testing.assert_allclose(m["surrogate_improvement"], improvement, atol=1e-4)
            np.testing.assert_allclose(m["kl"], kl, rtol=1e-3, atol=1e-6)
        else:
            assert leaves_equal(new.actor_params, state.actor_params)
        assert int(new.iterations) == i + 1
        np.testing.assert_allclose(m["mean_std"], np.exp(log_std_of(new)).mean(), rtol=1e-6)
        state = new
    assert accepted >= 3


def test_kl_check_rejects_steps_outside_the_trust_region():
    # The quadratic model of the KL underestimates this first step's KL, and SIL's line search
    # (no KL check) accepts the full step beyond max_kl; with the check, half of it is taken.
    results = {}
    for kl_check in (False, True):
        agent = small_agent(max_kl=0.5, kl_check=kl_check)
        state = agent.init(0)
        batch = bandit_batch(agent, state, jax.random.PRNGKey(0))
        new, m = agent.learn(state, batch)
        results[kl_check] = (measured_kl(agent, state, new, batch.obs), m)
    kl_unchecked, m_unchecked = results[False]
    kl_checked, m_checked = results[True]
    assert m_unchecked["step_fraction"] == 1.0 and kl_unchecked > 0.5
    assert m_checked["step_fraction"] == 0.5 and kl_checked <= 0.5
    np.testing.assert_allclose(m_unchecked["kl"], kl_unchecked, rtol=1e-3)


def test_rejected_step_keeps_the_actor_and_fits_the_value():
    agent = small_agent(accept_ratio=1e3)  # no step can do 1000x better than expected
    state = agent.init(0)
    batch = bandit_batch(agent, state, jax.random.PRNGKey(0), episode_length=4)
    new, m = agent.learn(state, batch)
    assert leaves_equal(new.actor_params, state.actor_params)
    assert m["step_fraction"] == m["kl"] == m["surrogate_improvement"] == 0.0
    assert int(new.iterations) == 1
    # The value fit still ran, on R = V_old + GAE (advantages before normalisation).
    v_old = np.asarray(agent.value(state, batch.obs), np.float64)
    target = v_old + gae(batch.reward, v_old, batch.episode_end, 0.99, 0.97)
    loss_before = np.mean((v_old - target) ** 2)
    loss_after = np.mean((np.asarray(agent.value(new, batch.obs)) - target) ** 2)
    np.testing.assert_allclose(m["value_loss"], loss_after, rtol=1e-4)
    assert loss_after < 0.5 * loss_before


def test_learn_is_deterministic():
    agent = small_agent()
    state = agent.init(0)
    batch = bandit_batch(agent, state, jax.random.PRNGKey(0))
    a, ma = agent.learn(state, batch)
    b, mb = agent.learn(state, batch)
    assert leaves_equal(a, b) and ma == mb
    assert set(ma) == {
        "value_loss",
        "surrogate_improvement",
        "kl",
        "step_fraction",
        "entropy",
        "mean_std",
    }
    assert all(type(x) is float for x in ma.values())


def test_learn_rejects_bad_batches():
    agent = small_agent()
    state = agent.init(0)
    good = bandit_batch(agent, state, jax.random.PRNGKey(0), n=8)
    with pytest.raises(ValueError, match="at least 2"):
        agent.learn(state, OnPolicyBatch(*(x[:1] for x in good)))
    for field in ("obs", "action", "reward"):
        bad = np.array(getattr(good, field), np.float64)
        bad.flat[3] = np.nan
        with pytest.raises(ValueError, match=rf"batch\.{field}"):
            agent.learn(state, good._replace(**{field: bad}))
    with pytest.raises(ValueError, match=r"batch\.obs"):
        agent.learn(state, good._replace(obs=good.obs[:, :1]))
    with pytest.raises(ValueError, match=r"batch\.action"):
        agent.learn(state, good._replace(action=good.action[:-1]))
    with pytest.raises(ValueError, match="episode end"):
        agent.learn(state, good._replace(episode_end=np.zeros(8, bool)))
    with pytest.raises(ValueError, match="booleans"):
        agent.learn(state, good._replace(episode_end=np.full(8, 2)))


def point_mass_batch(agent, state, key, episodes, seed=0):
    """A point mass in the plane, x' = x + 0.1 clip(a, -1, 1), reward -|x'|^2, 32-step
    episodes from x0 ~ U([-1, 1]^2), all episodes stepped at once; key None: the mean actions.
    Returns the batch and the mean return. (The sizes are the bandit's: no new compilation.)"""
    x = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(episodes, 2)).astype(np.float32)
    obs, actions, rewards = [], [], []
    for _ in range(32):
        k = None
        if key is not None:
            key, k = jax.random.split(key)
        a = np.asarray(agent.act(state, x, k))
        obs.append(x)
        actions.append(a)
        x = (x + 0.1 * np.clip(a, -1.0, 1.0)).astype(np.float32)
        rewards.append(-np.sum(x**2, axis=1))
    end = np.zeros((episodes, 32), bool)
    end[:, -1] = True
    batch = OnPolicyBatch(
        np.stack(obs, 1).reshape(-1, 2),
        np.stack(actions, 1).reshape(-1, 2),
        np.stack(rewards, 1).reshape(-1),
        end.reshape(-1),
    )
    return batch, float(batch.reward.sum() / episodes)


@pytest.mark.parametrize("code_fisher, iterations, closed", [(False, 8, 0.7), (True, 12, 0.4)])
def test_learns_point_mass(code_fisher, iterations, closed):
    """TRPO with the exact KL Hessian closes most of the gap in 8 iterations (measured 0.85-0.93
    over seeds 0-2); the authors' Fisher (2 I on the mean network too) takes several times
    shorter steps: 0.22-0.50 after 8 iterations, 0.53-0.79 after 12."""
    agent = small_agent(batch_steps=N, code_fisher=code_fisher)
    state = agent.init(0)
    _, initial = point_mass_batch(agent, state, None, 64, seed=99)
    key = jax.random.PRNGKey(0)
    for i in range(iterations):
        key, k = jax.random.split(key)
        batch, _ = point_mass_batch(agent, state, k, agent.batch_steps // 32, seed=i)
        state, _ = agent.learn(state, batch)
    _, final = point_mass_batch(agent, state, None, 64, seed=99)
    # Returns are <= 0; the initial (near-zero) policy stays where it starts.
    assert initial < -15
    assert final - initial > closed * -initial


@pytest.mark.slow
def test_learns_pendulum():
    """Pendulum-v1 in 20 iterations of 20 episodes (80k steps; ~30 s). gamma 0.95: with the
    SIL default 0.99 the value fit on Pendulum's long-horizon returns is too slow for this
    budget (as for every on-policy method there; RL Zoo's TRPO uses 0.9). The exact KL Hessian:
    the authors' Fisher (``code_fisher``) takes steps several times shorter."""
    gym = pytest.importorskip("gymnasium")
    episodes, horizon = 20, 200
    cfg = TRPOConfig(
        hidden=(64, 64),
        gamma=0.95,
        gae_lambda=0.95,
        batch_steps=episodes * horizon,
        code_fisher=False,
    )
    agent = make_trpo(cfg, 3, 1, max_action=2.0)
    # Angular velocity lies in [-8, 8]: scaled so that the +-5 clip keeps it.
    state = agent.set_normalizer(agent.init(0), np.zeros(3), [1.0, 1.0, 4.0])
    envs = [gym.make("Pendulum-v1") for _ in range(episodes)]

    def run(state, seeds, key=None):
        active = envs[: len(seeds)]
        obs = np.stack([env.reset(seed=s)[0] for env, s in zip(active, seeds, strict=True)])
        observations, actions, rewards = [], [], []
        for _ in range(horizon):
            k = None
            if key is not None:
                key, k = jax.random.split(key)
            action = np.asarray(agent.act(state, obs, k))  # raw; the env gets it clipped
            steps = [env.step(np.clip(a, -2.0, 2.0)) for env, a in zip(active, action, strict=True)]
            observations.append(obs)
            actions.append(action)
            rewards.append([s[1] for s in steps])
            obs = np.stack([s[0] for s in steps])
        end = np.zeros((len(obs), horizon), bool)
        end[:, -1] = True
        batch = OnPolicyBatch(
            np.stack(observations, 1).reshape(-1, 3),
            np.stack(actions, 1).reshape(-1, 1),
            np.array(rewards).T.reshape(-1),
            end.reshape(-1),
        )
        return batch, float(batch.reward.sum() / len(obs))

    eval_seeds = range(10_000, 10_010)
    _, initial = run(state, eval_seeds)
    key = jax.random.PRNGKey(1)
    for i in range(20):
        key, k = jax.random.split(key)
        batch, _ = run(state, range(i * episodes, (i + 1) * episodes), k)
        state, _ = agent.learn(state, batch)
    _, final = run(state, eval_seeds)
    print(f"TRPO Pendulum-v1: deterministic return {initial:.0f} -> {final:.0f}")
    assert initial < -900
    assert final > -400
