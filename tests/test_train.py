"""The training loop end to end, on tiny budgets (short horizon, fast preset)."""

import dataclasses
import json
import shutil

import numpy as np
import pytest

from ilfo.cli import main
from ilfo.training import TrainConfig, Trainer, load_demos, read_run_config
from ilfo.training.metrics import METRIC_FIELDS
from ilfo.training.migrations import upgrade_run_config
from ilfo.training.run_dir import latest_checkpoint
from tiny_run import DEMOS, TINY_RUN, metrics_rows, train_tiny


@pytest.mark.integration
def test_smoke_run_writes_everything(tmp_path):
    run = train_tiny(tmp_path, "run")
    for name in ("config.json", "metrics.csv", "policy.msgpack", "learning_curve.png"):
        assert (run / name).is_file(), name
    assert list((run / "tb").glob("events.out.tfevents.*"))
    assert (run / "best_policy.msgpack").is_file()
    rows = metrics_rows(run)
    assert [int(r["step"]) for r in rows] == [100, 200, 300, 400, 500, 600]
    evals = [r for r in rows if r["eval_score"]]
    assert len(evals) == 3 and all(r["eval_ot_distance"] for r in evals)
    assert all(r["critic_loss"] for r in rows[2:])  # updates begin with the policy


@pytest.mark.integration
def test_same_seed_same_numbers_and_resume_equals_uninterrupted(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full"))
    again = metrics_rows(train_tiny(tmp_path, "again"))
    assert full == again
    train_tiny(tmp_path, "resumed", steps=300)
    trainer = Trainer.resume(tmp_path / "resumed", progress=False, steps=600)
    assert trainer.step == 300
    assert metrics_rows(trainer.train()) == full
    other_seed = metrics_rows(train_tiny(tmp_path, "seed1", seed=1))
    assert other_seed != full


@pytest.mark.integration
def test_resume_with_oops_warm_starts_equals_uninterrupted(tmp_path):
    # Warm starts carry Sinkhorn potentials from episode to episode; a resume must restore them.
    warm = {"oops": {"warm_start": True, "tol": 1e-6}, "steps": 400}
    full = metrics_rows(train_tiny(tmp_path, "full", **warm))
    run = train_tiny(tmp_path, "resumed", **{**warm, "steps": 300})
    assert (run / "checkpoints" / "step_000000300" / "reward_arrays.npz").is_file()
    assert metrics_rows(Trainer.resume(run, progress=False, steps=400).train()) == full


@pytest.mark.integration
def test_resume_after_a_crash_drops_rows_logged_after_the_checkpoint(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full", steps=400))
    run = train_tiny(tmp_path, "crashed", steps=300)
    # A crash after step 400 was logged but before any checkpoint of it: a stale row.
    with (run / "metrics.csv").open("a") as f:  # complete: a torn row is dropped whatever its step
        f.write(",".join(["400", "4", "9.9", "1.0", "-1", "-1"] + [""] * (len(METRIC_FIELDS) - 6)))
        f.write("\n")
    trainer = Trainer.resume(run, progress=False, steps=400)
    assert [int(r["step"]) for r in metrics_rows(run)] == [100, 200, 300]
    assert metrics_rows(trainer.train()) == full


@pytest.mark.integration
def test_eval_of_the_final_policy_repeats_the_last_evaluation(tmp_path):
    """`ilfo eval` rolls out on the run's evaluation seeds, not the demos' (0, 1, ...): a
    finished run's final policy scores what its last evaluation (at its last step) logged."""
    from ilfo.evaluate import evaluate_run

    run = train_tiny(tmp_path, "run", steps=400)
    last = [r for r in metrics_rows(run) if r["eval_score"]][-1]
    assert last["step"] == "400"
    result = evaluate_run(run, episodes=1)
    assert round(result["score_mean"], 3) == float(last["eval_score"])
    assert round(result["ot_distance"], 5) == float(last["eval_ot_distance"])


@pytest.mark.integration
def test_a_run_past_its_budget_resumes_and_an_extended_one_drops_its_old_final_policy(tmp_path):
    """Whole 100-step episodes take a 250-step run to 300: resuming it is no shortening (it
    only writes its final policy again); extending it removes the 300-step final policy, which
    `ilfo eval` would otherwise take for the extended run's until it ends."""
    run = train_tiny(tmp_path, "run", steps=250)
    assert latest_checkpoint(run).name == "step_000000300"
    trainer = Trainer.resume(run, progress=False)
    assert trainer.step == 300 and (run / "policy.msgpack").is_file()
    trainer.train()
    assert (run / "policy.msgpack").is_file()
    with pytest.raises(ValueError, match="would shorten it"):
        Trainer.resume(run, progress=False, steps=200)
    extended = Trainer.resume(run, progress=False, steps=400)
    assert not (run / "policy.msgpack").exists()
    extended.train()
    assert (run / "policy.msgpack").is_file()


def _replace(path, data):  # as the loop writes its files: a new file renamed over the old
    tmp = path.with_name(path.name + ".new")
    tmp.write_bytes(data)
    tmp.replace(path)


@pytest.mark.integration
def test_resume_puts_back_the_checkpoints_best_policy(tmp_path):
    """A best policy written after the last checkpoint (by a later evaluation) is from a future
    the resume discards: the checkpoint's copy goes back, so that the best policy's record
    matches the metrics rows whatever the continuation does."""
    run = train_tiny(tmp_path, "run", steps=400)
    young = shutil.copytree(run, tmp_path / "young")
    ckpt = latest_checkpoint(run)
    kept = {n: (ckpt / n).read_bytes() for n in ("best_policy.msgpack", "best_policy.json")}
    assert kept["best_policy.json"] == (run / "best_policy.json").read_bytes()
    future = {**json.loads(kept["best_policy.json"]), "step": 500, "eval_score": 1e9}
    _replace(run / "best_policy.json", json.dumps(future).encode())
    _replace(run / "best_policy.msgpack", b"a policy of a discarded future")
    trainer = Trainer.resume(run, progress=False)
    assert {n: (run / n).read_bytes() for n in kept} == kept
    trainer._lock.release()
    # A checkpoint of an earlier ilfo holds no copy: a newer best policy stays, with a warning.
    for name in kept:
        (ckpt / name).unlink()
    _replace(run / "best_policy.json", json.dumps(future).encode())
    with pytest.warns(UserWarning, match="from step 500, after checkpoint"):
        Trainer.resume(run, progress=False)._lock.release()
    assert json.loads((run / "best_policy.json").read_text())["step"] == 500
    # A finished run whose checkpoints were removed is not started again from 0: its best
    # policy stays (test_rundir: one killed before its first checkpoint starts again).
    shutil.rmtree(young / "checkpoints")
    best = {n: (young / n).read_bytes() for n in kept}
    with pytest.raises(ValueError, match="no complete checkpoint"):
        Trainer.resume(young, progress=False)
    assert {n: (young / n).read_bytes() for n in kept} == best


@pytest.mark.integration
def test_td7_same_seed_same_numbers_and_resume_equals_uninterrupted(tmp_path):
    # TD7's state (fixed and target encoders, the clipping range) must survive a checkpoint.
    td7 = {
        "algo": "oops-td7",
        "td7": {
            "zs_dim": 16,
            "encoder_hidden": 16,
            "actor_hidden": 16,
            "critic_hidden": 16,
            "target_update_every": 50,
        },
    }
    full = metrics_rows(train_tiny(tmp_path, "full", **td7))
    assert full == metrics_rows(train_tiny(tmp_path, "again", **td7))
    train_tiny(tmp_path, "resumed", **td7, steps=300)
    assert (
        metrics_rows(Trainer.resume(tmp_path / "resumed", progress=False, steps=600).train())
        == full
    )


@pytest.mark.integration
@pytest.mark.parametrize("algo", ["oops-ddpg", "oops-sac", "oops-td7", "pwil-td3", "td3", "td7"])
def test_every_algo_runs(tmp_path, algo):
    rows = metrics_rows(train_tiny(tmp_path, algo, algo=algo, steps=300))
    assert int(rows[-1]["step"]) >= 300
    evals = [r for r in rows if r["eval_score"]]
    assert evals and rows[-1]["critic_loss"]
    if algo in ("td3", "td7"):  # the task reward, in standard mode: episodes end at falls
        assert int(rows[0]["step"]) < 100 and not evals[-1]["eval_ot_distance"]


@pytest.mark.integration
def test_cli_train_and_eval_and_plot(tmp_path, capsys):
    args = ["train", "--no-progress", "--out", str(tmp_path), "--steps", "300"]
    for key, value in TINY_RUN.items():
        args += [f"--{key.replace('_', '-')}", str(value)]
    assert main(args) == 0
    (run,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert run.name.startswith("Hopper-v5__oops-td3__0__")
    capsys.readouterr()
    assert main(["eval", str(run), "--episodes", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["episodes"] == 2 and "score_norm" in result
    assert result["policy"] == "policy.msgpack"
    assert main(["eval", str(run), "--episodes", "1", "--best", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["policy"] == "best_policy.msgpack"
    out = tmp_path / "curves.png"
    assert main(["plot", str(run), "--out", str(out)]) == 0
    assert out.stat().st_size > 0
    assert main(["plot", str(run), "--out", str(out), "--metric", "critic_loss"]) == 0
    assert main(["plot", str(run), "--out", str(out), "--metric", "nosuch"]) == 2
    assert "no metric 'nosuch'" in capsys.readouterr().err
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    (damaged / "config.json").write_bytes((run / "config.json").read_bytes())
    text = (run / "metrics.csv").read_text().splitlines()
    column = text[0].split(",").index("eval_score_norm")
    rows = [line.split(",") for line in text[1:]]
    next(r for r in reversed(rows) if r[column])[column] = "abc"
    (damaged / "metrics.csv").write_text("\n".join([text[0], *map(",".join, rows)]) + "\n")
    assert main(["plot", str(damaged), "--out", str(out)]) == 2
    assert "metrics.csv: eval_score_norm 'abc' at step" in capsys.readouterr().err
    (damaged / "metrics.csv").write_text(text[0] + "\n")  # no evaluation yet
    assert main(["plot", str(damaged), "--out", str(out)]) == 2
    assert "nothing to plot: no evaluation logged yet" in capsys.readouterr().err


@pytest.mark.integration
def test_imitation_on_ant_drops_the_contact_forces_by_default_from_the_run_and_its_demos(
    tmp_path,
):
    from ilfo.evaluate import evaluate_run
    from ilfo.experiments.distances import final_rollouts
    from ilfo.training import load_demo_set

    ant = {**TINY_RUN, "env": "Ant-v5", "demos": None, "num_demos": 1}
    run = train_tiny(tmp_path, "ant", **ant, steps=300)
    assert json.loads((run / "config.json").read_text())["contact_forces"] is False
    demos = load_demo_set(TrainConfig(**ant), obs_dim=27)  # the shipped 105-dim demos, sliced
    assert demos.observations[0].shape == (1001, 27)
    rows = metrics_rows(run)
    assert len(rows) == 3 and rows[1]["eval_score"] and rows[1]["eval_ot_distance"]
    rollouts, experts = final_rollouts(run, episodes=1, experts=1)
    assert rollouts[0].observations.shape[1] == experts[0].observations.shape[1] == 27
    # The 27-column policy evaluates as training evaluated it (its one evaluation, the best).
    evaluated = evaluate_run(run, episodes=1, best=True)["score_mean"]
    assert round(evaluated, 3) == float(rows[1]["eval_score"])
    with pytest.raises(ValueError, match="have observations of dimension 105"):
        load_demo_set(TrainConfig(**{**ant, "contact_forces": True}), obs_dim=27)


def test_contact_forces_default_to_off_for_imitation_on_ant_and_humanoid_only():
    from ilfo.training import config_from_dict, config_from_settings

    def observes(**kw):
        return TrainConfig(**kw).observes_contact_forces

    assert not observes(env="Humanoid-v5") and not observes(env="Ant-v5", algo="pwil-td3")
    assert observes(env="Humanoid-v5", algo="td3") and observes(env="Ant-v5", algo="sac")
    assert observes(env="Ant-v5", contact_forces=True) and not observes(
        env="Ant-v5", algo="sac", contact_forces=False
    )
    assert observes(env="Hopper-v5") and observes(env="Hopper-v5", contact_forces=True)
    with pytest.raises(ValueError, match="applies to Ant-v5, Humanoid-v5, not Hopper-v5"):
        TrainConfig(env="Hopper-v5", contact_forces=False)
    # config.json records what the run observed, not None.
    assert TrainConfig(env="Ant-v5").resolved(1000).contact_forces is False
    # A record written before the setting existed observed them (migrations upgrades it when
    # read: tests/test_compat.py); settings without it default.
    old = config_from_dict(upgrade_run_config({"env": "Ant-v5"}, "old config.json"), "old")
    assert old.contact_forces is True
    assert config_from_settings({"env": "Ant-v5"}, "spec").observes_contact_forces is False


@pytest.mark.integration
def test_a_reward_that_did_not_converge_is_reported_once(tmp_path):
    from ilfo.rewards import OOPSConfig

    oops = OOPSConfig(max_iter=1, tol=1e-12, solver="sinkhorn")
    config = TrainConfig(**{**TINY_RUN, "steps": 300, "eval_every": 300, "oops": oops})
    trainer = Trainer(config, tmp_path / "run", progress=False)
    with pytest.warns(UserWarning, match="sinkhorn coupling did not converge") as caught:
        trainer.train()
    assert len([w for w in caught if "did not converge" in str(w.message)]) == 1
    assert trainer.unconverged_rewards == 3  # every episode, reported once


def test_demos_whose_return_is_zero_leave_scores_unnormalised(tmp_path):
    """Nothing to divide by: the scores are left unnormalised (a ZeroDivisionError at the
    first evaluation before)."""
    from ilfo import demos
    from ilfo.training.build import load_demo_set

    zeroed = [dataclasses.replace(e, rewards=np.zeros_like(e.rewards))
              for e in demos.load(DEMOS).episodes[:2]]  # fmt: skip
    path = tmp_path / "d.npz"
    demos.save(path, zeroed, "Hopper-v5")
    config = TrainConfig(**{**TINY_RUN, "demos": str(path), "num_demos": 2})
    assert np.isnan(load_demo_set(config, 11).mean_return)


def test_demos_in_which_the_expert_fell_are_named_in_a_warning(tmp_path):
    import warnings

    from ilfo import demos

    episodes = demos.load(DEMOS).episodes[:3]
    path = tmp_path / "d.npz"
    demos.save(path, episodes, "Hopper-v5", {"seeds": [4, 5, 6], "kept_seeds_with_a_fall": [5]})
    config = TrainConfig(**{**TINY_RUN, "demos": str(path), "num_demos": 1})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(load_demos(config)) == 1  # seed 4: no fall, no warning
    with pytest.warns(UserWarning, match=r"fell .* seeds \[5\]"):
        load_demos(TrainConfig(**{**TINY_RUN, "demos": str(path), "num_demos": 3}))


@pytest.mark.integration
def test_a_run_records_the_demo_file_it_imitates_and_warns_if_it_changes(tmp_path):
    """demos.json ties a run to its demo file's bytes: a resume on a file replaced since (an
    expert re-exported) warns and keeps the first record; a run older than the record gets one
    from the step it resumed at."""
    import hashlib
    import shutil

    from ilfo import demos

    path = tmp_path / "d.npz"
    shutil.copy(DEMOS, path)
    run = train_tiny(tmp_path, "run", demos=str(path), num_demos=2, steps=200)
    record = json.loads((run / "demos.json").read_text())
    first_sha = hashlib.sha256(path.read_bytes()).hexdigest()
    assert record["sha256"] == first_sha and record["path"] == str(path.resolve())
    episodes = demos.load(path).episodes
    assert record["num_demos"] == 2 and record["since_step"] == 0
    assert record["mean_return"] == pytest.approx(np.mean([e.task_score for e in episodes[:2]]))

    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the same file: no warning
        Trainer.resume(run, progress=False, steps=300)._lock.release()
    demos.save(path, episodes[::-1], "Hopper-v5")  # the file replaced
    with pytest.warns(UserWarning, match="not the demo file this run started on"):
        Trainer.resume(run, progress=False, steps=300)._lock.release()
    assert json.loads((run / "demos.json").read_text())["sha256"] == first_sha

    (run / "demos.json").unlink()  # a run from before the record, and its format numbers
    config = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({k: v for k, v in config.items() if k != "format"}))
    Trainer.resume(run, progress=False, steps=300)._lock.release()
    record = json.loads((run / "demos.json").read_text())
    assert record["since_step"] == 200 and record["sha256"] != first_sha

    task_reward = train_tiny(tmp_path, "td3", algo="td3", steps=200)
    assert not (task_reward / "demos.json").exists()


def test_cli_shows_a_warning_as_one_line(tmp_path, capsys):
    from ilfo import demos

    # No env id, and Hopper's states: a Walker2d run stops at the dimension check.
    path = tmp_path / "d.npz"
    demos.save(
        path, demos.load(DEMOS).episodes[:1], "", {"seeds": [0], "kept_seeds_with_a_fall": [0]}
    )
    argv = ["train", "--env", "Walker2d-v5", "--demos", str(path), "--out", str(tmp_path / "runs")]
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("ilfo: warning: ") and "seeds [0]" in err[0]
    assert err[1].startswith("ilfo: error: ") and "dimension" in err[1]


def test_cli_errors(tmp_path, capsys):
    assert (
        main(
            [
                "train",
                "--demos",
                str(tmp_path / "missing.npz"),
                "--no-progress",
                "--out",
                str(tmp_path / "runs"),
            ]
        )
        == 2
    )
    assert "no demonstration file" in capsys.readouterr().err
    out = ["--out", str(tmp_path / "runs")]
    assert main(["train", "--env", "NoSuchEnv-v0", "--no-progress", *out]) == 2
    assert "unknown environment" in capsys.readouterr().err
    assert not list((tmp_path / "runs").iterdir())  # a failed start leaves no run directory
    assert main(["train", "--resume", str(tmp_path)]) == 2
    assert "not a run directory" in capsys.readouterr().err
    assert main(["train", "--steps", "0", "--demos", DEMOS]) == 2
    assert "steps must be >= 1" in capsys.readouterr().err
    # Zeros and negatives are errors, not the default silently (a 0 horizon used to run 1,000).
    for flags, message in (
        (["--horizon", "0"], "horizon must be >= 1"),
        (["--seed", "-1"], "seed must be >= 0"),
        (["--td3-gamma", "2"], "gamma must be in (0, 1]"),
        (["--td3-tau", "0"], "tau must be in (0, 1]"),
    ):
        assert main(["train", *flags, "--demos", DEMOS, "--no-progress", *out]) == 2
        assert message in capsys.readouterr().err
    assert not list((tmp_path / "runs").iterdir())
    with pytest.raises(SystemExit):
        main(["train", "--algo", "gail"])
    with pytest.raises(SystemExit):
        main(["train", "--steps", "many"])
    assert main(["eval", str(tmp_path)]) == 2


@pytest.mark.integration
def test_cli_agent_and_rewarder_flags_reach_config_json_and_resume(tmp_path, capsys):
    args = ["train", "--no-progress", "--out", str(tmp_path), "--steps", "300"]
    for key, value in TINY_RUN.items():
        args += [f"--{key.replace('_', '-')}", str(value)]
    args += ["--td3-batch-size", "32", "--td3-critic-hidden", "64", "64"]
    args += ["--td3-critic-grad-clip", "none", "--oops-reg", "0.1", "--seed", "2"]
    assert main(args) == 0
    (run,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    saved = json.loads((run / "config.json").read_text())
    td3, oops = saved["td3"], saved["oops"]
    assert td3["batch_size"] == 32 and td3["critic_hidden"] == [64, 64]
    assert td3["critic_grad_clip"] is None
    # The rest is the fast preset's, with what the trainer sets: max_time is the horizon.
    assert td3["tau"] == 0.003 and td3["loss"] == "pal" and td3["max_time"] == 100
    assert oops["reg"] == 0.1 and oops["seed"] == 2 and oops["solver"] == "sinkhorn"
    assert saved["sac"] is None and saved["pwil"] is None
    config = TrainConfig(**read_run_config(run))  # config.json's settings beside its format
    assert config.td3.critic_hidden == (64, 64) and config.oops.reg == 0.1

    assert main(["train", "--resume", str(run), "--steps", "400", "--no-progress"]) == 0
    assert int(metrics_rows(run)[-1]["step"]) == 400
    resaved = json.loads((run / "config.json").read_text())
    assert resaved == {**saved, "steps": 400}
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--td3-tau", "0.1", "--oops-reg", "1"]) == 2
    assert "drop --td3-tau, --oops-reg" in capsys.readouterr().err


def test_cli_flags_of_another_algo_are_a_clear_error(capsys):
    assert main(["train", "--sac-tau", "0.01", "--demos", DEMOS, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "sac settings (--sac-* flags) do not apply to algo 'oops-td3'" in err
    assert "Traceback" not in err
    assert main(["train", "--algo", "sac", "--oops-reg", "0.1", "--no-progress"]) == 2
    assert "oops settings (--oops-* flags) do not apply to algo 'sac'" in capsys.readouterr().err
    assert main(["train", "--oops-adv-critic-lr", "0.001", "--demos", DEMOS, "--no-progress"]) == 2
    assert "(--oops-adv-* flags) do not apply" in capsys.readouterr().err  # the flags' spelling
    assert main(["train", "--oops-reg", "-1", "--demos", DEMOS, "--no-progress"]) == 2
    assert "reg must be positive" in capsys.readouterr().err


@pytest.mark.integration
def test_ctrl_c_mid_episode_finishes_the_episode_checkpoints_and_resumes_exactly(tmp_path):
    import os
    import signal

    from ilfo.training import LoopHooks

    class InterruptInEpisode3(LoopHooks):
        def episode_rewarded(self, trainer, output):
            # Inside episode 3, as a user's Ctrl-C would land; its end, step 300, is no
            # scheduled checkpoint (every 200): the stop request alone makes it.
            if trainer.episode == 3:
                os.kill(os.getpid(), signal.SIGINT)

    full = metrics_rows(train_tiny(tmp_path, "full"))
    config = TrainConfig(**{**TINY_RUN, "steps": 600})
    hooks = InterruptInEpisode3()
    trainer = Trainer(config, tmp_path / "interrupted", progress=False, hooks=hooks)
    with pytest.raises(KeyboardInterrupt):
        trainer.train()
    run = tmp_path / "interrupted"
    assert latest_checkpoint(run).name == "step_000000300"
    resumed = Trainer.resume(run, progress=False)
    assert resumed.step == 300
    assert metrics_rows(resumed.train()) == full


def test_network_normalizer_weighs_expert_and_random_states_alike_as_the_paper_code():
    import numpy as np

    from ilfo.training import network_normalizer

    rng = np.random.default_rng(0)
    random_states = rng.normal(0.0, 0.1, (1000, 3))
    random_states[:, 2] = 5.0  # a constant dimension: std 0 becomes 1
    expert = rng.normal(3.0, 1.0, (100, 3))
    mean, std = network_normalizer(random_states, [expert])
    np.testing.assert_allclose(mean, random_states.mean(axis=0))
    # The demo counts ten times, so that both halves weigh the same.
    pooled = np.concatenate([random_states] + [expert] * 10)
    np.testing.assert_allclose(std[:2], pooled[:, :2].std(axis=0, ddof=1))
    assert std[0] > 1.0  # far more than the 1:10 count weighting would give (~0.96)
    # Without demos (task reward): the random states' own std, floored at 0.33.
    _, alone = network_normalizer(random_states, [])
    np.testing.assert_allclose(alone, [0.33, 0.33, 1.0])


@pytest.mark.integration
@pytest.mark.parametrize("updates_per_step", [1, 3])
def test_updates_per_step_sets_the_update_count(tmp_path, updates_per_step):
    config = TrainConfig(**{**TINY_RUN, "steps": 400, "updates_per_step": updates_per_step})
    trainer = Trainer(config, tmp_path / "run", progress=False)
    trainer.train()
    # Updates follow every episode collected by the policy (steps 200-400), none the random ones.
    assert int(trainer.state.step) == 200 * updates_per_step


def test_updates_per_step_below_one_is_an_error():
    with pytest.raises(ValueError, match="updates_per_step must be >= 1"):
        TrainConfig(**{**TINY_RUN, "updates_per_step": 0})
    # On-policy TRPO (sil) learns once per batch: more updates per step would be ignored.
    with pytest.raises(ValueError, match="updates_per_step does not apply to algo 'sil'"):
        TrainConfig(**{**TINY_RUN, "algo": "sil", "updates_per_step": 4})
    assert TrainConfig(**{**TINY_RUN, "algo": "sil"}).updates_per_step == 1


def test_a_replay_buffer_smaller_than_an_episode_is_refused_at_the_start(tmp_path):
    config = TrainConfig(**{**TINY_RUN, "replay_capacity": 99})  # the horizon is 100
    with pytest.raises(ValueError, match=r"replay_capacity .* at least the horizon, 100; got 99"):
        Trainer(config, tmp_path / "run", progress=False)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("steps", 1e6),
        ("updates_per_step", 2.0),
        ("seed", "0"),
        ("horizon", 10.5),
        ("num_demos", True),
    ],
)
def test_counts_that_are_not_integers_are_an_error(field, value):
    with pytest.raises(ValueError, match=f"{field} must be an integer"):
        TrainConfig(**{**TINY_RUN, field: value})


def test_evaluation_episodes_past_the_maximum_are_refused_up_front(tmp_path, capsys):
    """A billion evaluation episodes (a typo) built a billion seeds at the first evaluation,
    and the kernel killed the run at 23 GB with no message: the config refuses them before a
    run directory is made, and `ilfo eval --episodes` by the same check before it loads."""
    from ilfo.training.config import MAX_EVAL_EPISODES

    most = TrainConfig(**{**TINY_RUN, "eval_episodes": MAX_EVAL_EPISODES})
    assert most.eval_episodes == MAX_EVAL_EPISODES
    too_many = MAX_EVAL_EPISODES + 1
    message = rf"eval_episodes \(--eval-episodes\) must be from 1 to {MAX_EVAL_EPISODES:,}"
    with pytest.raises(ValueError, match=rf"{message} .*got {too_many:,}"):
        TrainConfig(**{**TINY_RUN, "eval_episodes": too_many})
    out = tmp_path / "runs"
    argv = ["train", "--eval-episodes", "1000000000", "--demos", DEMOS, "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "--eval-episodes" in err and "got 1,000,000,000" in err
    assert not out.exists() or not list(out.iterdir())
    run = tmp_path / "a-run"  # checked before the run is read: its state does not matter
    for episodes in ("1000000000", "0"):
        assert main(["eval", str(run), "--episodes", episodes]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "--episodes must be from 1 to" in err


def test_numpy_integers_are_taken_as_ints():
    config = TrainConfig(**{**TINY_RUN, "seed": np.int64(3), "steps": np.int32(400)})
    assert type(config.seed) is int and type(config.steps) is int
    assert json.loads(json.dumps(dataclasses.asdict(config)))["seed"] == 3


@pytest.mark.integration
def test_a_relative_demos_path_is_recorded_absolute(tmp_path, monkeypatch, capsys):
    # Recorded as given, `ilfo eval RUN` and `--resume` from another directory could not find
    # the demos.
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(DEMOS, work / "demos.npz")
    monkeypatch.chdir(work)
    run = train_tiny(tmp_path, "run", demos="demos.npz", steps=200)
    recorded = json.loads((run / "config.json").read_text())["demos"]
    assert recorded == str(work / "demos.npz")
    monkeypatch.chdir(tmp_path)
    assert main(["eval", str(run), "--episodes", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["episodes"] == 1


@pytest.mark.integration
def test_scores_are_not_normalised_by_a_negative_demo_return(tmp_path):
    # Pendulum's returns are negative: a learner at -1404 over a demo at -123 read 11.4.
    from ilfo import demos as demo_io

    rng = np.random.default_rng(0)
    episode = demo_io.Episode(
        observations=rng.normal(size=(201, 3)).astype(np.float32), rewards=np.full(200, -0.6)
    )
    path = tmp_path / "pendulum.npz"
    demo_io.save(path, [episode], env_id="Pendulum-v1")
    settings = {**TINY_RUN, "env": "Pendulum-v1", "demos": str(path), "horizon": None, "steps": 400}
    with pytest.warns(UserWarning, match="mean return is -120, not positive"):
        run = Trainer(TrainConfig(**settings), tmp_path / "run", progress=False).train()
    evals = [r for r in metrics_rows(run) if r["eval_score"]]
    assert evals and all(r["eval_score_norm"] == "" for r in evals)
    assert float(evals[-1]["eval_score"]) < 0
