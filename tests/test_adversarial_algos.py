"""SIL-(s,s') (TRPO, on-policy) and OOPS_adv (TD3) end to end through the training loop."""

import itertools
import json

import numpy as np
import pytest

from ilfo.cli import main
from ilfo.training import TrainConfig, Trainer
from tiny_run import TINY_RUN as TINY_RUN
from tiny_run import metrics_rows, train_tiny

SIL_TINY = dict(
    algo="sil",
    fixed_horizon=True,  # 100-step episodes: the batches below end where the test says
    trpo={"hidden": (16, 16), "batch_steps": 200, "value_iters": 5},
    sil={"critic_hidden": (16, 16), "critic_features": 8, "expert_subsample": 5},
)
OOPS_ADV_TINY = dict(
    algo="oops-adv-td3",
    oops_adv={"critic_hidden": (16, 16), "critic_features": 8},
    td3={"actor_hidden": (32, 32), "critic_hidden": (32, 32)},
)


@pytest.mark.integration
def test_sil_learns_once_per_batch_deterministically_and_resumes_mid_batch(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full", **SIL_TINY))
    assert full == metrics_rows(train_tiny(tmp_path, "again", **SIL_TINY))
    # No random phase: TRPO acts from the first step; 100-step episodes, a batch of 200 steps:
    # the agent and the critic learn after every second episode, and only then.
    learned = [int(r["step"]) for r in full if r["critic_loss"]]
    assert learned == [200, 400, 600]
    assert [int(r["step"]) for r in full if r["reward_loss"]] == learned
    assert all(float(r["proxy_return"]) != 0 for r in full)
    # Stopped after 300 steps: half a batch pending (in the buffer and in the critic's state).
    run = train_tiny(tmp_path, "resumed", **{**SIL_TINY, "steps": 300})
    trainer = Trainer.resume(run, progress=False, steps=600)
    assert trainer.step == 300
    assert metrics_rows(trainer.train()) == full


@pytest.mark.integration
def test_an_on_policy_policy_is_evaluated_again_only_after_it_learns(tmp_path):
    from ilfo.training import LoopHooks

    class CountEvaluations(LoopHooks):
        evaluations = 0

        def timed(self, piece):
            if piece == "evaluate":
                self.evaluations += 1
            return super().timed(piece)

    hooks = CountEvaluations()
    config = TrainConfig(**{**TINY_RUN, **SIL_TINY, "steps": 600, "eval_every": 100})
    run = Trainer(config, tmp_path / "run", progress=False, hooks=hooks).train()
    rows = metrics_rows(run)
    assert all(r["eval_score"] for r in rows)  # every episode's row has its evaluation
    # Learns at 200, 400 and 600: evaluated at 100 (the first), 200, 400 and 600 only; the
    # rows between repeat the last evaluation of the same policy.
    assert hooks.evaluations == 4
    by_step = {int(r["step"]): r["eval_score"] for r in rows}
    assert by_step[300] == by_step[200] and by_step[500] == by_step[400]


@pytest.mark.integration
def test_oops_adv_trains_deterministically_and_resume_equals_uninterrupted(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full", **OOPS_ADV_TINY))
    assert full == metrics_rows(train_tiny(tmp_path, "again", **OOPS_ADV_TINY))
    assert all(float(r["proxy_return"]) < 0 for r in full)  # minus a transported cost
    run = train_tiny(tmp_path, "resumed", **{**OOPS_ADV_TINY, "steps": 300})
    trainer = Trainer.resume(run, progress=False, steps=600)
    assert metrics_rows(trainer.train()) == full


@pytest.mark.integration
def test_oops_adv_reward_differs_from_oops_with_a_fixed_cosine_cost(tmp_path):
    adv = metrics_rows(train_tiny(tmp_path, "adv", **{**OOPS_ADV_TINY, "steps": 200}))
    cos = metrics_rows(
        train_tiny(
            tmp_path,
            "cos",
            algo="oops-td3",
            oops={"metric": "cosine"},
            steps=200,
            td3=OOPS_ADV_TINY["td3"],
        )
    )
    assert [r["proxy_return"] for r in adv] != [r["proxy_return"] for r in cos]


@pytest.mark.integration
def test_sil_flags_reach_config_json_and_the_policy_reads_back(tmp_path, capsys):
    args = ["train", "--algo", "sil", "--env", "Hopper-v5", "--demos", TINY_RUN["demos"]]
    args += ["--horizon", "50", "--steps", "100", "--eval-every", "100", "--eval-episodes", "1"]
    args += ["--out", str(tmp_path), "--no-progress", "--trpo-batch-steps", "100"]
    args += ["--trpo-hidden", "16", "16", "--sil-critic-lr", "0.001", "--sil-expert-subsample", "4"]
    assert main(args) == 0
    (run,) = tmp_path.iterdir()
    config = json.loads((run / "config.json").read_text())
    assert config["trpo"]["batch_steps"] == 100 and config["trpo"]["hidden"] == [16, 16]
    assert config["sil"]["critic_lr"] == 0.001 and config["sil"]["expert_subsample"] == 4
    assert config["sil"]["seed"] == config["seed"]
    assert config["td3"] is None and config["oops"] is None
    capsys.readouterr()
    assert main(["eval", str(run), "--episodes", "1", "--json"]) == 0
    evaluated = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert evaluated["episodes"] == 1 and np.isfinite(evaluated["score_mean"])


@pytest.mark.integration
def test_sil_trains_on_standard_episodes_by_default_and_learns_per_batch(tmp_path):
    assert not TrainConfig(algo="sil").uses_fixed_horizon  # the authors' code: falls end them
    assert TrainConfig(algo="oops-adv-td3").uses_fixed_horizon  # ilfo's imitation protocol
    standard = {k: v for k, v in SIL_TINY.items() if k != "fixed_horizon"}
    rows = metrics_rows(train_tiny(tmp_path, "run", **{**standard, "steps": 400}))
    # A random Hopper falls within tens of steps: episodes end there, and a batch is whole
    # episodes of at least 200 steps.
    assert int(rows[0]["step"]) < 100
    learned = [int(r["step"]) for r in rows if r["critic_loss"]]
    assert learned and learned[0] >= 200
    assert all(b - a >= 200 for a, b in itertools.pairwise(learned))


def test_trpo_and_sil_settings_do_not_apply_to_other_algos():
    with pytest.raises(ValueError, match="trpo settings"):
        TrainConfig(algo="oops-td3", trpo={"max_kl": 0.01})
    with pytest.raises(ValueError, match="sil settings"):
        TrainConfig(algo="oops-adv-td3", sil={"reg": 0.1})
    with pytest.raises(ValueError, match="oops_adv settings"):
        TrainConfig(algo="sil", oops_adv={"reg": 0.1})


def test_unbounded_actions_are_clipped_for_the_environment_but_learned_as_drawn():
    from ilfo.training.rollout import env_action

    np.testing.assert_array_equal(env_action(np.array([-3.0, 0.5, 2.0]), 1.0), [-1.0, 0.5, 1.0])
    inside = np.array([0.25, -0.75], np.float32)
    assert env_action(inside, 1.0).dtype == np.float64
    np.testing.assert_array_equal(env_action(inside, 1.0), inside.astype(np.float64))
