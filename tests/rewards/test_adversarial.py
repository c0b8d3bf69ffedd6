"""SIL's adversarial critic (rewards/adversarial.py), the SIL-(s,s') reward (rewards/sil.py) and
OOPS_adv (rewards/oops_adv.py)."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import cdist

from ilfo.ot import sinkhorn
from ilfo.rewards import RewardState, Standardizer, make_atoms
from ilfo.rewards.adversarial import (
    AdversarialCritic,
    cosine_cost,
    critic_arrays,
    load_critic_arrays,
)
from ilfo.rewards.oops_adv import AdversarialOOPS, AdversarialOOPSConfig
from ilfo.rewards.sil import SIL, RunningStd, SILConfig

OBS_DIM = 3


def _episode(rng, steps, offset=0.0):
    """A smooth random walk (steps + 1, OBS_DIM)."""
    return np.cumsum(rng.normal(offset, 0.3, (steps + 1, OBS_DIM)), axis=0)


def _demos(seed=0, count=2, steps=100):
    rng = np.random.default_rng(seed)
    return [_episode(rng, steps) for _ in range(count)]


def _leaves(params):
    return [np.asarray(x) for x in jax.tree.leaves(params)]


def _same_params(a, b):
    return all(np.array_equal(x, y) for x, y in zip(_leaves(a), _leaves(b), strict=True))


def _roundtrip(state: RewardState) -> RewardState:
    """What a checkpoint does to a reward state: values through JSON, arrays copied."""
    values = json.loads(json.dumps(state.values))
    return RewardState(values, {k: np.array(v) for k, v in state.arrays.items()})


# --- the cosine cost --------------------------------------------------------------------------


def test_cosine_cost_matches_scipy():
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(20, 7)), rng.normal(size=(9, 7))
    with jax.enable_x64(True):
        cost = np.asarray(jax.jit(cosine_cost)(x, y))
    np.testing.assert_allclose(cost, cdist(x, y, "cosine"), rtol=0, atol=1e-12)
    cost32 = np.asarray(jax.jit(cosine_cost)(x.astype(np.float32), y.astype(np.float32)))
    np.testing.assert_allclose(cost32, cdist(x, y, "cosine"), atol=1e-5)


def test_cosine_cost_of_zero_features_is_finite_with_finite_gradients():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(4, 5)).astype(np.float32)
    y = rng.normal(size=(3, 5)).astype(np.float32)
    x[1], y[2] = 0.0, 0.0
    cost = np.asarray(jax.jit(cosine_cost)(x, y))
    assert np.isfinite(cost).all()
    np.testing.assert_allclose(cost[1], 1.0)  # a zero vector is orthogonal to everything
    np.testing.assert_allclose(cost[:, 2], 1.0)
    weights = rng.uniform(size=(4, 3)).astype(np.float32)
    transported = lambda a, b: jnp.sum(weights * cosine_cost(a, b))  # noqa: E731
    gx, gy = jax.jit(jax.grad(transported, argnums=(0, 1)))(x, y)
    assert np.isfinite(np.asarray(gx)).all() and np.isfinite(np.asarray(gy)).all()


# --- the critic -------------------------------------------------------------------------------


def test_critic_is_torch_initialised_and_its_cost_is_in_range():
    critic = AdversarialCritic((128, 128), 30)
    state = critic.init(jax.random.PRNGKey(0), 6)
    layers = state.params["params"]["Dense_0"], state.params["params"]["Dense_2"]
    for layer, fan_in in zip(layers, (6, 128), strict=True):
        bound = 1.0 / np.sqrt(fan_in)
        assert np.abs(layer["kernel"]).max() <= bound and np.abs(layer["bias"]).max() <= bound
        assert np.abs(layer["kernel"]).max() > 0.9 * bound  # uniform over the whole range
    assert layers[1]["kernel"].shape == (128, 30)
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(70, 6)), rng.normal(size=(5, 6))
    cost = critic.cost(state.params, x, y)  # on atoms padded to 128 and 64 rows
    assert cost.shape == (70, 5) and cost.dtype == np.float64
    assert cost.min() >= 0.0 and cost.max() <= 2.0
    features = [np.asarray(jax.jit(critic.features)(state.params, a), np.float64) for a in (x, y)]
    np.testing.assert_allclose(cost, cdist(*features, "cosine"), atol=1e-5)


@settings(max_examples=5, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    n=st.integers(10, 64),
    m=st.integers(3, 64),
)
def test_critic_steps_increase_the_sinkhorn_distance(seed, n, m):
    rng = np.random.default_rng(seed)
    x, y = rng.normal(0.0, 1.0, (n, 6)), rng.normal(0.5, 1.0, (m, 6))
    critic = AdversarialCritic(lr=1e-3)
    state = critic.init(jax.random.PRNGKey(seed), 6)
    distances = []
    for _ in range(6):
        result = sinkhorn(critic.cost(state.params, x, y), reg=0.01, max_iter=100_000)
        assert result.converged
        distances.append(result.cost)
        state, loss = critic.step(state, [(x, y, result.plan)])
        assert loss == pytest.approx(-result.cost, rel=1e-5)  # N = 1: divisor max(0, 1)
    assert distances[-1] > distances[0]


def _fd_problem():
    """A small critic in float64 and three (learner, expert, plan) pairs (must run under x64)."""
    critic = AdversarialCritic((16, 16), 5)
    state = critic.init(jax.random.PRNGKey(0), 4)
    params = jax.tree.map(lambda a: np.asarray(a, np.float64), state.params)
    rng = np.random.default_rng(0)
    atoms = [(rng.normal(size=(12, 4)), rng.normal(1.0, 1.0, size=(7, 4))) for _ in range(3)]
    return critic, params, atoms


def _plans(critic, params, atoms):
    return [
        sinkhorn(critic.cost(params, x, y), reg=0.05, tol=1e-13, max_iter=100_000).plan
        for x, y in atoms
    ]


def _nudged(params, leaf, index, h):
    """``params`` with entry ``index`` of leaf number ``leaf`` moved by ``h`` (numpy leaves)."""
    leaves, treedef = jax.tree.flatten(params)
    leaves = [x.copy() for x in leaves]
    leaves[leaf].flat[index] += h
    return jax.tree.unflatten(treedef, leaves)


def test_critic_gradient_holds_the_plan_fixed():
    with jax.enable_x64(True):
        critic, params, atoms = _fd_problem()
        pairs = [(x, y, p) for (x, y), p in zip(atoms, _plans(critic, params, atoms), strict=True)]
        loss, grads = critic.loss_and_grad(params, pairs)
        # -(1 / (N - 1)) sum <P, C>, N = 3.
        total = sum(np.sum(p * critic.cost(params, x, y)) for x, y, p in pairs)
        assert loss == pytest.approx(-total / 2, rel=1e-12)
        # The padded, jitted, pair-by-pair gradient is the reference expression's.
        reference = jax.jit(critic.loss)
        for got, want in zip(
            jax.tree.leaves(grads),
            jax.tree.leaves(jax.jit(jax.grad(critic.loss))(params, pairs)),
            strict=True,
        ):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)

        def resolved(p):  # the transported cost with the plans solved again at p
            plans = _plans(critic, p, atoms)
            pairs = zip(atoms, plans, strict=True)
            return -sum(np.sum(pl * critic.cost(p, x, y)) for (x, y), pl in pairs) / 2

        h = 1e-6
        grad_leaves = jax.tree.leaves(grads)
        for leaf, index in ((0, 0), (1, 7), (3, 100), (5, 4)):  # biases and kernels, all layers
            up, down = _nudged(params, leaf, index, h), _nudged(params, leaf, index, -h)
            fixed = float(reference(up, pairs) - reference(down, pairs)) / (2 * h)
            moving = (resolved(up) - resolved(down)) / (2 * h)
            grad = float(grad_leaves[leaf].flat[index])
            assert grad == pytest.approx(fixed, rel=1e-6, abs=1e-9)
            # Differentiating through the plan would give another gradient.
            assert abs(grad - moving) > 1e-4


def test_critic_arrays_round_trip_and_shape_errors():
    critic = AdversarialCritic()
    state = critic.init(jax.random.PRNGKey(0), 6)
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(5, 6)), rng.normal(size=(3, 6))
    state, _ = critic.step(state, [(x, y, np.full((5, 3), 1 / 15))])
    arrays = critic_arrays(state)
    assert "critic/opt_state/0/count" in arrays and "critic/params/params/Dense_0/kernel" in arrays
    fresh = critic.init(jax.random.PRNGKey(1), 6)
    restored = load_critic_arrays(fresh, arrays)
    assert _same_params(restored.params, state.params)
    assert _same_params(restored.opt_state, state.opt_state)
    wider = dict(arrays)  # as a critic of 31 features would have it
    wider["critic/params/params/Dense_2/kernel"] = np.zeros((128, 31), np.float32)
    with pytest.raises(ValueError, match=r"Dense_2/kernel has shape \(128, 31\)"):
        load_critic_arrays(fresh, wider)
    del arrays["critic/opt_state/0/count"]
    with pytest.raises(ValueError, match="missing"):
        load_critic_arrays(fresh, arrays)


# --- SIL --------------------------------------------------------------------------------------


def test_running_std_filter_by_hand():
    values = [2.0, -1.0, 4.0, 0.5, 30.0]
    expected = [2.0 / (2.0 + 1e-8)]  # the first value over its own magnitude
    for k in range(2, len(values) + 1):
        expected.append(values[k - 1] / (np.std(values[:k], ddof=1) + 1e-8))
    filt = RunningStd(clip=10.0)
    np.testing.assert_allclose(filt(np.array(values[:2])), expected[:2], rtol=1e-12)
    np.testing.assert_allclose(filt(np.array(values[2:])), expected[2:], rtol=1e-12)
    assert filt.count == 5 and filt.mean == pytest.approx(np.mean(values))
    assert filt.m2 == pytest.approx(np.var(values) * 5)
    clipped = RunningStd(clip=1.5)(np.array(values))
    np.testing.assert_allclose(clipped, np.clip(expected, -1.5, 1.5), rtol=1e-12)
    assert clipped.max() == 1.5  # 30 / std is 2.16


def test_sil_rewards_are_the_filtered_raw_rewards():
    demos = _demos()
    sil = SIL(demos, SILConfig(expert_subsample=5))
    rng = np.random.default_rng(3)
    filt = RunningStd(clip=10.0)
    for steps in (80, 40):
        out = sil(_episode(rng, steps, 0.05))
        assert out.coupling.converged and out.rewards.shape == (steps,)
        raw = -2.0 * out.coupling.row_costs + 4.0 / steps
        assert raw.min() >= -1e-12 and raw.max() <= 4.0 / steps + 1e-12
        assert raw.sum() == pytest.approx(4.0 - 2.0 * out.distance)
        np.testing.assert_allclose(out.rewards, filt(raw), rtol=1e-12)
        assert out.demo_index in (0, 1)
    assert sil.reward_filter.count == 120


def test_sil_normalises_with_the_demos_fixed_clipped_z_score():
    demos = _demos()
    demos[0][:, 2] = 7.0  # a constant dimension: std 0 becomes 1
    sil = SIL(demos, SILConfig(obs_clip=2.0))
    states = np.concatenate([d[:-1] for d in demos])
    std = np.maximum(states.std(axis=0, ddof=1), 0.33)
    obs = np.array([[0.0, 0.0, 0.0], [1e3, -1e3, 0.0]])
    expected = np.clip((obs - states.mean(axis=0)) / std, -2.0, 2.0)
    np.testing.assert_allclose(sil.normalize(obs), expected)


def test_sil_expert_draw_subsamples_with_true_next_states():
    rng = np.random.default_rng(0)
    demos = [_episode(rng, 1000), _episode(rng, 1000)]
    sil = SIL(demos, SILConfig(seed=4))
    norm = sil.normalize(demos[1])
    draw = sil.expert_draw(1, 7)
    assert draw.shape == (50, 2 * OBS_DIM)
    kept = np.arange(7, 1000, 20)
    np.testing.assert_array_equal(draw[:, :OBS_DIM], norm[kept])
    np.testing.assert_array_equal(draw[:, OBS_DIM:], norm[kept + 1])  # s_t+1, not s_t+20
    # The episode is matched to the demo and phase drawn by the seeded generator, in that order.
    episode = _episode(rng, 200)
    out = sil(episode)
    expected = np.random.default_rng(4)
    demo, phase = int(expected.integers(2)), int(expected.integers(20))
    assert out.demo_index == demo and out.coupling.plan.shape == (200, 50)
    cost = sil.critic.cost(
        sil.critic_state.params,
        make_atoms(sil.normalize(episode), "transitions"),
        sil.expert_draw(demo, phase),
    )
    np.testing.assert_array_equal(
        out.coupling.plan, sinkhorn(cost, reg=0.01, max_iter=100_000).plan
    )
    every = SIL(demos, SILConfig(expert_subsample=1))
    assert every(episode).coupling.plan.shape == (200, 1000)


def test_sil_end_batch_without_episodes_does_nothing():
    sil = SIL(_demos())
    params = sil.critic_state.params
    assert sil.end_batch() == {}
    assert sil.critic_state.params is params
    sil(_episode(np.random.default_rng(0), 50))
    metrics = sil.end_batch()
    assert set(metrics) == {"reward_loss", "reward_mean", "reward_distance"}
    assert not _same_params(sil.critic_state.params, params)
    assert sil.pending_episodes == 0 and sil.end_batch() == {}


def test_sil_end_batch_steps_on_the_batch():
    rng = np.random.default_rng(5)
    episodes = [_episode(rng, steps, 0.1) for steps in (60, 60, 90)]
    sil = SIL(_demos(), SILConfig(expert_subsample=4))
    outs = [sil(e) for e in episodes]
    before = sil.critic_state
    metrics = sil.end_batch()
    distances = [o.distance for o in outs]
    assert metrics["reward_loss"] == pytest.approx(-sum(distances) / 2, rel=1e-5)
    assert metrics["reward_distance"] == pytest.approx(np.mean(distances))
    assert metrics["reward_mean"] == pytest.approx(np.concatenate([o.rewards for o in outs]).mean())
    # The step is the critic's step on these (learner, expert, plan) pairs.
    atoms = [make_atoms(sil.normalize(e), "transitions") for e in episodes]
    expected = np.random.default_rng(0)
    pairs = []
    for x, o in zip(atoms, outs, strict=True):
        demo, phase = int(expected.integers(2)), int(expected.integers(4))
        pairs.append((x, sil.expert_draw(demo, phase), o.coupling.plan))
    stepped, _ = sil.critic.step(before, pairs)
    assert _same_params(sil.critic_state.params, stepped.params)


def test_sil_is_deterministic_under_its_seed():
    demos = _demos(count=3)
    rng = np.random.default_rng(2)
    episodes = [_episode(rng, 70) for _ in range(4)]

    def run(seed):
        sil = SIL(demos, SILConfig(seed=seed, expert_subsample=3))
        rewards = [sil(e).rewards for e in episodes[:2]]
        sil.end_batch()
        return rewards + [sil(e).rewards for e in episodes[2:]]

    a, b, c = run(0), run(0), run(1)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(np.array_equal(x, y) for x, y in zip(a, c, strict=True))


def test_sil_resume_in_the_middle_of_a_batch_is_exact():
    demos = _demos(count=3)
    rng = np.random.default_rng(7)
    episodes = [_episode(rng, steps, 0.05) for steps in (60, 80, 60, 70, 60)]
    config = SILConfig(expert_subsample=6, seed=3)

    full = SIL(demos, config)
    first = [full(e).rewards for e in episodes[:2]]
    full.end_batch()
    full(episodes[2])
    full(episodes[3])
    metrics_full = full.end_batch()
    last_full = full(episodes[4])

    part = SIL(demos, config)
    for episode, rewards in zip(episodes[:2], first, strict=True):  # the same run up to here
        np.testing.assert_array_equal(part(episode).rewards, rewards)
    part.end_batch()
    part(episodes[2])
    saved = _roundtrip(part.state())
    assert saved.values["pending"][0]["demo"] in (0, 1, 2) and "pending/0" in saved.arrays

    resumed = SIL(demos, config)
    resumed.load_state(saved)
    assert resumed.pending_episodes == 1
    resumed(episodes[3])
    assert resumed.end_batch() == metrics_full
    assert _same_params(resumed.critic_state.params, full.critic_state.params)
    assert _same_params(resumed.critic_state.opt_state, full.critic_state.opt_state)
    last = resumed(episodes[4])
    np.testing.assert_array_equal(last.rewards, last_full.rewards)
    assert last.demo_index == last_full.demo_index
    assert resumed.reward_filter.state() == full.reward_filter.state()


def test_sil_rejects_bad_input_and_bad_state():
    with pytest.raises(ValueError, match="expert_subsample"):
        SILConfig(expert_subsample=0)
    with pytest.raises(ValueError, match="reg"):
        SILConfig(reg=0.0)
    # A float where an int belongs, or inf or NaN: refused when the config is made (a settings
    # file goes through dataclasses.replace, which checks no types).
    import dataclasses

    for config in (SILConfig(), AdversarialOOPSConfig()):
        for bad, match in (
            ({"max_iter": 1e5}, "max_iter must be an int >= 1"),
            ({"tol": float("inf")}, "tol must be positive and finite"),
            ({"critic_lr": float("nan")}, "critic_lr must be positive and finite"),
        ):
            with pytest.raises(ValueError, match=match):
                dataclasses.replace(config, **bad)
    assert SILConfig(obs_clip=float("inf")).obs_clip == float("inf")  # no clipping
    sil = SIL(_demos())
    with pytest.raises(ValueError, match="dimension"):
        sil(np.zeros((10, OBS_DIM + 1)))
    bad = np.zeros((10, OBS_DIM))
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        sil(bad)
    state = sil.state()  # as atoms of another dimension would have it
    state.arrays["critic/params/params/Dense_0/kernel"] = np.zeros((8, 128), np.float32)
    with pytest.raises(ValueError, match="shape"):
        sil.load_state(state)
    sil(_episode(np.random.default_rng(0), 20))
    state = sil.state()
    state.arrays["pending/0"] = np.zeros((20, 2 * OBS_DIM + 2))
    with pytest.raises(ValueError, match="pending episode 0"):
        sil.load_state(state)


# --- OOPS_adv ---------------------------------------------------------------------------------


def test_oops_adv_rewards_have_oops_sign_and_scale():
    demos = _demos(count=2, steps=120)
    rewarder = AdversarialOOPS(demos)
    initial = rewarder.critic_state.params
    episode = _episode(np.random.default_rng(1), 100, 0.1)
    out = rewarder(episode)
    scale = 5.0 * 100 / np.sqrt(OBS_DIM)
    assert out.rewards.shape == (100,) and (out.rewards <= 0).all()
    assert out.rewards.min() >= -2.0 * scale / 100  # C <= 2 and each row carries 1 / T
    assert out.rewards.sum() == pytest.approx(-scale * out.distance)
    assert out.coupling.plan.shape == (100, 120)  # the whole demo: no subsampling
    # The rewards are the critic's before its step, with OOPS's standardised atoms.
    standardizer = Standardizer.from_demos(demos)
    cost = rewarder.critic.cost(
        initial,
        make_atoms(standardizer(episode), "transitions"),
        make_atoms(standardizer(demos[out.demo_index]), "transitions"),
    )
    expected = -scale * sinkhorn(cost, reg=0.05, max_iter=20000).row_costs
    np.testing.assert_allclose(out.rewards, expected, rtol=1e-12)


def test_oops_adv_critic_steps_every_k_episodes():
    demos = _demos(steps=60)
    rng = np.random.default_rng(4)
    episodes = [_episode(rng, 50) for _ in range(6)]
    every = AdversarialOOPS(demos)
    for e in episodes[:3]:
        before = every.critic_state.params
        every(e)
        assert not _same_params(before, every.critic_state.params)
    third = AdversarialOOPS(demos, AdversarialOOPSConfig(critic_every=3))
    changed = []
    for e in episodes:
        before = third.critic_state.params
        third(e)
        changed.append(not _same_params(before, third.critic_state.params))
    assert changed == [False, False, True, False, False, True]


def test_oops_adv_resume_with_pending_episodes_is_exact():
    demos = _demos(count=3, steps=60)
    rng = np.random.default_rng(9)
    episodes = [_episode(rng, 50) for _ in range(6)]
    config = AdversarialOOPSConfig(critic_every=3, seed=2)
    full = AdversarialOOPS(demos, config)
    outs_full = [full(e) for e in episodes]
    part = AdversarialOOPS(demos, config)
    [part(e) for e in episodes[:4]]
    saved = _roundtrip(part.state())
    assert len(saved.values["pending"]) == 1
    resumed = AdversarialOOPS(demos, config)
    resumed.load_state(saved)
    for e, out in zip(episodes[4:], outs_full[4:], strict=True):
        np.testing.assert_array_equal(resumed(e).rewards, out.rewards)
    assert _same_params(resumed.critic_state.params, full.critic_state.params)
    assert _same_params(resumed.critic_state.opt_state, full.critic_state.opt_state)


def test_oops_adv_rejects_bad_input():
    with pytest.raises(ValueError, match="critic_every"):
        AdversarialOOPSConfig(critic_every=0)
    with pytest.raises(ValueError, match="different observation dimensions"):
        AdversarialOOPS([np.ones((5, 3)), np.ones((5, 4))])
    rewarder = AdversarialOOPS(_demos(steps=30))
    with pytest.raises(ValueError, match="dimension"):
        rewarder(np.zeros((10, OBS_DIM + 2)))
    bad = np.ones((10, OBS_DIM))
    bad[0, 0] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        rewarder(bad)
