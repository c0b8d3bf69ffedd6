"""OPOLO and its inverse dynamics model."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ilfo.agents.inverse_dynamics import (
    InverseDynamics,
    InverseDynamicsConfig,
    RunningMoments,
    update_moments,
)
from ilfo.composition.learned import LearnedRewardSetup, RewardSchedule
from ilfo.composition.opolo import OPOLOConfig, make_opolo
from ilfo.replay import ReplayData
from ilfo.rewards import Discriminator, DiscriminatorConfig, expert_transitions
from ilfo.training import Trainer, load_run_policy
from tiny_run import metrics_rows, train_tiny


def test_running_moments_equal_the_pooled_mean_and_variance():
    rng = np.random.default_rng(0)
    batches = [rng.normal(2.0, 3.0, (n, 4)).astype(np.float32) for n in (10, 50, 7)]
    moments = RunningMoments.create(4)
    for batch in batches:
        moments = update_moments(moments, jnp.asarray(batch))
    pooled = np.concatenate(batches)
    # The pseudo-count 1e-2 at mean 0, variance 1 weighs 1e-2 / 67 of the result.
    c, n = 1e-2, len(pooled)
    mean = pooled.sum(0) / (c + n)
    var = (c * 1.0 + c * mean**2 + ((pooled - mean) ** 2).sum(0)) / (c + n)
    np.testing.assert_allclose(moments.mean, mean, rtol=1e-4)
    np.testing.assert_allclose(moments.var, var, rtol=1e-3)
    assert float(moments.count) == pytest.approx(c + n)


def test_inverse_dynamics_recovers_the_actions_of_a_linear_system():
    rng = np.random.default_rng(1)
    a_mat = rng.normal(0, 0.5, (3, 3))
    b_mat = rng.normal(0, 1.0, (2, 3))
    s = rng.normal(size=(4000, 3))
    a = rng.uniform(-1, 1, (4000, 2))
    s_next = s @ a_mat + a @ b_mat
    obs, act, nxt = (jnp.asarray(x, jnp.float32) for x in (s, a, s_next))
    idm = InverseDynamics(InverseDynamicsConfig(hidden=(64, 64), lr=3e-3, l2=0.0), 3, 2)
    state = idm.init(jax.random.PRNGKey(0))
    update = jax.jit(idm.update)
    key = jax.random.PRNGKey(1)
    for _ in range(1500):
        key, k = jax.random.split(key)
        idx = jax.random.randint(k, (128,), 0, 3000)
        state, _ = update(state, obs[idx], act[idx], nxt[idx])
    held = slice(3000, 4000)
    error = jnp.mean((idm.predict(state, obs[held], nxt[held]) - act[held]) ** 2)
    assert float(error) < 0.01 * float(jnp.var(act))  # R^2 > 0.99 on held-out transitions


def _opolo(**overrides):
    rng = np.random.default_rng(0)
    demo = rng.normal(size=(80, 4)).astype(np.float32)
    expert = expert_transitions([demo], min_count=16)
    reward = Discriminator(DiscriminatorConfig(hidden=(16,), batch_size=16))
    setup = LearnedRewardSetup(reward, RewardSchedule(20, 2), expert, expert.obs, False)
    cfg = OPOLOConfig(
        actor_hidden=(16,), critic_hidden=(16,), idm_hidden=(16,), batch_size=16,
        idm_pretrain_steps=5, idm_every=20, idm_steps=3, **overrides,
    )  # fmt: skip
    agent = make_opolo(cfg, 4, 2, 1.0, setup)
    n = 100
    data = ReplayData(
        jnp.asarray(rng.normal(size=(n, 4)), jnp.float32),
        jnp.asarray(rng.uniform(-1, 1, (n, 2)), jnp.float32),
        jnp.zeros(n, jnp.float32),
        jnp.asarray(rng.normal(size=(n, 4)), jnp.float32),
        jnp.ones(n, jnp.float32),
    )
    return agent, data, expert


def test_opolo_without_its_actor_terms_leaves_the_actor_unchanged():
    agent, data, _ = _opolo(alpha=0.0, pi_reg_coef=0.0)
    state = agent.init(0)
    new, metrics = agent.update(state, data, 100, num_updates=40)
    for x, y in zip(*map(jax.tree.leaves, (state.actor_params, new.actor_params)), strict=True):
        np.testing.assert_array_equal(x, y)
    assert int(new.step) == 40 and bool(new.idm_pretrained)
    assert {"critic_loss", "reward_loss", "idm_loss"} <= set(metrics)
    # The critics learned, and their targets followed on the actor's updates.
    for before, after in zip(
        *map(jax.tree.leaves, (state.critic_target, new.critic_target)), strict=True
    ):
        assert not np.array_equal(before, after)


def test_opolo_regulariser_pulls_the_policy_to_the_inverse_dynamics_actions():
    agent, data, expert = _opolo(alpha=0.0, pi_reg_coef=1.0, lr=3e-3)
    idm = InverseDynamics(InverseDynamicsConfig(hidden=(16,)), 4, 2)  # the agent's model's shape
    state = agent.init(0)
    trained, _ = agent.update(state, data, 100, num_updates=200)
    # The model learns too: measure both policies against the trained model's actions.
    target = idm.predict(trained.idm, expert.obs, expert.next_obs)
    gap_before = float(jnp.mean((agent.act(state, expert.obs) - target) ** 2))
    gap_after = float(jnp.mean((agent.act(trained, expert.obs) - target) ** 2))
    assert gap_after < 0.5 * gap_before


def test_opolo_updates_ignore_the_stored_rewards():
    agent, data, _ = _opolo()
    state = agent.init(0)
    a, _ = agent.update(state, data, 100, num_updates=30)
    b, _ = agent.update(state, data._replace(reward=data.reward + 1e3), 100, num_updates=30)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)


OPOLO = dict(
    algo="opolo",
    discriminator={"update_every": 50, "updates": 2, "batch_size": 32, "hidden": (32, 32)},
    opolo={"actor_hidden": (32, 32), "critic_hidden": (32, 32), "idm_hidden": (32,),
           "idm_pretrain_steps": 20, "idm_every": 50, "idm_steps": 5},
)  # fmt: skip


@pytest.mark.integration
def test_opolo_trains_deterministically_and_resume_equals_uninterrupted(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full", **OPOLO))
    assert full == metrics_rows(train_tiny(tmp_path, "again", **OPOLO))
    assert any(r["reward_loss"] for r in full) and any(r["critic_loss"] for r in full)
    run = train_tiny(tmp_path, "resumed", **{**OPOLO, "steps": 300})
    latest = load_run_policy(run, "latest")  # a checkpoint of the whole state reads back
    assert latest.checkpoint is not None and latest.checkpoint.loop.step == 300
    trainer = Trainer.resume(run, progress=False, steps=600)
    assert metrics_rows(trainer.train()) == full


def test_opolo_defaults_follow_the_authors_per_env():
    from ilfo.training import TrainConfig

    hopper = TrainConfig(env="Hopper-v5", algo="opolo")
    assert hopper.part_config("opolo") == OPOLOConfig.hopper()
    assert hopper.part_config("discriminator").lr == 1e-4
    walker = TrainConfig(env="Walker2d-v5", algo="opolo")
    assert walker.part_config("opolo") == OPOLOConfig()
    assert walker.part_config("discriminator").lr == 3e-4
    with pytest.raises(ValueError, match="td3 settings"):
        TrainConfig(algo="opolo", td3={"lr_actor": 1e-3})
