"""Agents trained on a learned reward (ilfo.composition.learned), and gaifo-td3 end to end."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ilfo.agents import TD3Config, make_td3
from ilfo.cli import main
from ilfo.composition.learned import LearnedRewardSetup, RewardSchedule, with_learned_reward
from ilfo.replay import ReplayData
from ilfo.rewards import Discriminator, DiscriminatorConfig, expert_transitions
from ilfo.training import Trainer
from tiny_run import TINY_RUN as TINY_RUN
from tiny_run import metrics_rows, train_tiny

SMALL_DISC = {"update_every": 50, "updates": 2, "batch_size": 32, "hidden": (32, 32)}


def test_reward_schedule_counts_the_multiples_crossed():
    schedule = RewardSchedule(every=500, steps=10)
    assert schedule.steps_due(0, 499) == 0
    assert schedule.steps_due(0, 500) == 10
    assert schedule.steps_due(499, 1) == 10
    assert schedule.steps_due(500, 499) == 0
    assert schedule.steps_due(100, 2000) == 40
    # Chunks of any sizes take the steps of one call: 1000 updates as 512 + 256 + ... + 8.
    done, total = 0, 0
    for chunk in (512, 256, 128, 64, 32, 8):
        total += schedule.steps_due(done, chunk)
        done += chunk
    assert total == schedule.steps_due(0, 1000) == 20


def _composed(time_feature=False):
    rng = np.random.default_rng(0)
    obs_dim = 4 + int(time_feature)
    demo = rng.normal(size=(60, 4)).astype(np.float32)
    expert = expert_transitions([demo], min_count=32)
    agent = make_td3(TD3Config(actor_hidden=(16,), critic_hidden=(16,), batch_size=32), obs_dim, 2)
    reward = Discriminator(DiscriminatorConfig(**SMALL_DISC))
    setup = LearnedRewardSetup(reward, RewardSchedule(50, 2), expert, expert.obs, time_feature)
    composed = with_learned_reward(agent, setup)
    n = 200
    data = ReplayData(
        jnp.asarray(rng.normal(size=(n, obs_dim)), jnp.float32),
        jnp.asarray(rng.uniform(-1, 1, (n, 2)), jnp.float32),
        jnp.zeros(n, jnp.float32),
        jnp.asarray(rng.normal(size=(n, obs_dim)), jnp.float32),
        jnp.ones(n, jnp.float32),
    )
    return composed, data


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree.leaves(tree)]


def test_updates_use_the_learned_reward_not_the_stored_one():
    composed, data = _composed()
    state = composed.init(0)
    a, metrics = composed.update(state, data, 200, num_updates=60)
    garbage = data._replace(reward=jnp.full_like(data.reward, 1e6))
    b, _ = composed.update(state, garbage, 200, num_updates=60)
    for x, y in zip(_leaves(a), _leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)
    assert "reward_loss" in metrics  # 60 updates cross 50: the reward took its steps
    assert int(a.updates) == 60 and int(a.agent.step) == 60
    # The reward learned, and the agent's batches are rewarded by its current parameters.
    before = composed.rewards(state, data.obs, data.next_obs)
    after = composed.rewards(a, data.obs, data.next_obs)
    assert not np.allclose(before, after)


def test_the_reward_never_sees_the_time_feature():
    composed, data = _composed(time_feature=True)
    state = composed.init(0)
    shifted = data._replace(
        obs=data.obs.at[:, -1].set(0.3), next_obs=data.next_obs.at[:, -1].set(0.9)
    )
    _, m1 = composed.update(state, data, 200, num_updates=50)
    _, m2 = composed.update(state, shifted, 200, num_updates=50)
    assert float(m1["reward_loss"]) == float(m2["reward_loss"])


GAIFO = dict(algo="gaifo-td3", discriminator=SMALL_DISC, td3={"actor_hidden": (32, 32),
             "critic_hidden": (32, 32)})  # fmt: skip


@pytest.mark.integration
def test_gaifo_td3_trains_deterministically_and_resume_equals_uninterrupted(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full", **GAIFO))
    assert full == metrics_rows(train_tiny(tmp_path, "again", **GAIFO))
    learned_rows = [r for r in full if r["reward_loss"]]
    # Logged as a fraction of a batch (a sum, or a NaN, would leave [0, 1]); this tiny run is
    # too short for the discriminator to beat a coin, which test_discriminator.py tests.
    accuracies = [float(r["reward_accuracy"]) for r in learned_rows]
    assert learned_rows and all(0.0 <= a <= 1.0 for a in accuracies)
    assert all(float(r["proxy_return"]) > 0 for r in full)  # -log(1 - D) > 0
    run = train_tiny(tmp_path, "resumed", **{**GAIFO, "steps": 300})
    trainer = Trainer.resume(run, progress=False, steps=600)
    assert trainer.step == 300
    assert metrics_rows(trainer.train()) == full


@pytest.mark.integration
def test_gaifo_td3_defaults_to_the_authors_td3_and_flags_reach_config_json(tmp_path, capsys):
    args = ["train", "--algo", "gaifo-td3", "--env", "Hopper-v5", "--demos", TINY_RUN["demos"]]
    args += ["--horizon", "50", "--steps", "100", "--start-steps", "100", "--eval-every", "100"]
    args += ["--eval-episodes", "1", "--out", str(tmp_path), "--no-progress"]
    args += ["--discriminator-lr", "0.001", "--discriminator-batch-size", "16"]
    assert main(args) == 0
    (run,) = tmp_path.iterdir()
    config = json.loads((run / "config.json").read_text())
    assert config["discriminator"]["lr"] == 0.001
    assert config["discriminator"]["batch_size"] == 16
    assert config["td3"]["actor_hidden"] == [400, 300]  # the DACfO authors', not the preset's
    assert config["td3"]["init_scheme"] == "glorot"
    assert config["oops"] is None
    capsys.readouterr()
    assert main(["eval", str(run), "--episodes", "1", "--json"]) == 0  # the policy reads back
    evaluated = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert evaluated["episodes"] == 1 and np.isfinite(evaluated["score_mean"])


def test_too_few_demo_transitions_for_a_batch_is_a_clear_error(tmp_path):
    from ilfo.training import TrainConfig

    config = TrainConfig(**{**TINY_RUN, **GAIFO, "discriminator": {"batch_size": 100_000}})
    with pytest.raises(ValueError, match="fewer than a batch of 100000"):
        Trainer(config, tmp_path / "run", progress=False)


def test_discriminator_flags_do_not_apply_to_oops():
    from ilfo.training import TrainConfig

    with pytest.raises(ValueError, match="discriminator settings"):
        TrainConfig(algo="oops-td3", discriminator={"lr": 1e-3})


FIRL_TINY = dict(
    algo="firl-fkl",
    firl={"iteration_steps": 200, "rollouts": 2, "disc_steps": 10, "disc_batch_size": 64,
          "reward_hidden": (16, 16), "disc_hidden": 16},
    sac={"actor_hidden": (32, 32), "critic_hidden": (32, 32), "batch_size": 64},
)  # fmt: skip


@pytest.mark.integration
def test_firl_trains_deterministically_and_resume_equals_uninterrupted(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full", **FIRL_TINY))
    assert full == metrics_rows(train_tiny(tmp_path, "again", **FIRL_TINY))
    # The reward learns once per 200 steps (600 steps: three times), from fresh rollouts.
    assert sum(bool(r["reward_loss"]) for r in full) == 3
    run = train_tiny(tmp_path, "resumed", **{**FIRL_TINY, "steps": 300})
    trainer = Trainer.resume(run, progress=False, steps=600)
    assert metrics_rows(trainer.train()) == full


def test_firl_defaults_follow_the_authors():
    from ilfo.rewards import FIRLConfig
    from ilfo.training import TrainConfig

    hopper = TrainConfig(env="Hopper-v5", algo="firl-fkl")
    sac = hopper.part_config("sac")
    assert (sac.lr_actor, sac.batch_size, sac.init_temperature, sac.autotune) == (
        1e-3, 100, 0.2, False,
    )  # fmt: skip
    assert hopper.part_config("firl") == FIRLConfig()
    ant = TrainConfig(env="Ant-v5", algo="firl-fkl").part_config("firl")
    assert ant.reward_hidden == (128, 128) and ant.disc_blocks == 6
    # The authors' SAC: standard episodes (a fall ends one) after 1000 random steps.
    assert not hopper.uses_fixed_horizon and hopper.random_steps == 1000
    assert hopper.resolved(1000).start_steps == 1000  # config.json records the number
    given = TrainConfig(env="Hopper-v5", algo="firl-fkl", start_steps=50, fixed_horizon=True)
    assert given.uses_fixed_horizon and given.random_steps == 50
    oops = TrainConfig(env="Hopper-v5", algo="oops-td3")
    assert oops.uses_fixed_horizon and oops.random_steps == 10_000  # ilfo's protocol


def test_expert_transitions_checks_its_demos_clearly():
    demo = np.arange(12, dtype=np.float32).reshape(4, 3)
    one = expert_transitions(demo)  # one demo as a 2-D array: as [demo], as the episode rewards
    listed = expert_transitions([demo])
    np.testing.assert_array_equal(one.obs, listed.obs)
    np.testing.assert_array_equal(one.next_obs, listed.next_obs)
    with pytest.raises(ValueError, match="demo 1 contains NaN or inf"):
        expert_transitions([demo, np.where(demo == 5, np.nan, demo)])
    with pytest.raises(ValueError, match="different observation dimensions: \\[3, 4\\]"):
        expert_transitions([demo, np.zeros((5, 4))])
    with pytest.raises(ValueError, match="at least one"):
        expert_transitions(np.zeros((0, 4, 3)))


@pytest.mark.integration
def test_learned_rewards_see_the_demos_up_to_the_horizon(tmp_path, monkeypatch):
    """With --horizon 100 below the demos' length, the discriminator's expert transitions and
    the agent's expert observations are each demo's first 100 (time features in [0, 1])."""
    import ilfo.training.build as build
    from ilfo.training import TrainConfig

    seen = {}

    def capture(**kwargs):
        seen.update(kwargs)
        return LearnedRewardSetup(**kwargs)

    monkeypatch.setattr(build, "LearnedRewardSetup", capture)
    config = TrainConfig(**{**TINY_RUN, **GAIFO, "num_demos": 2})
    trainer = Trainer(config, tmp_path / "run", progress=False)
    assert all(len(d) > 101 for d in trainer.demos)  # longer than the horizon
    assert seen["expert_agent_obs"].shape[0] == len(seen["expert"].obs) == 2 * 100
    for k, demo in enumerate(trainer.demos):  # each demo's first 100 transitions, in order
        rows = slice(100 * k, 100 * (k + 1))
        np.testing.assert_allclose(seen["expert"].obs[rows], demo[:100], rtol=1e-6)
        np.testing.assert_allclose(seen["expert"].next_obs[rows], demo[1:101], rtol=1e-6)
    times = np.asarray(seen["expert_agent_obs"][:, -1])
    assert times.min() > 0 and times.max() <= 1
