import dataclasses
import json
import shutil

import numpy as np
import pytest

from ilfo import demos
from ilfo.cli import main
from ilfo.experts import (
    DEMOS_FILE,
    collect_demos,
    evaluate_expert,
    expert_reward_scale,
    export_expert,
    load_expert,
    write_card,
)
from ilfo.training import TrainConfig, Trainer, read_metrics

TINY_SAC = TrainConfig(
    algo="sac",
    steps=400,
    start_steps=200,
    horizon=100,
    eval_every=400,
    eval_episodes=1,
    checkpoint_every=400,
    replay_capacity=2000,
)


def _metric_rows(run):
    rows = read_metrics(run)
    for row in rows:  # wall-clock columns differ between runs by nature
        del row["wall_time"], row["steps_per_s"]
    return rows


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("runs") / "expert"
    Trainer(TINY_SAC, run, progress=False).train()
    return run


def test_expert_reward_scales():
    assert expert_reward_scale("MinitaurBulletEnv-v0") == 16.0  # tiny per-step rewards
    assert expert_reward_scale("Hopper-v5") == 1.0


@pytest.mark.integration
def test_sac_resume_equals_uninterrupted(tiny_run, tmp_path):
    # Experts train in segments: a resumed SAC run (temperature, optimisers, replay, keys)
    # must give the numbers of one never interrupted.
    run = tmp_path / "segments"
    Trainer(dataclasses.replace(TINY_SAC, steps=300), run, progress=False).train()
    Trainer.resume(run, progress=False, steps=400).train()
    assert _metric_rows(run) == _metric_rows(tiny_run)


@pytest.mark.integration
def test_export_load_collect_and_card(tiny_run, tmp_path):
    out = export_expert(tiny_run, tmp_path / "Hopper-v5")
    expert = load_expert(out)
    assert expert.horizon == 100
    episodes = collect_demos(expert, 2, out / DEMOS_FILE, skip_falls=False)  # it falls
    loaded = demos.load(out / DEMOS_FILE)
    assert loaded.env_id == "Hopper-v5" and len(loaded.episodes) == 2
    for got, want in zip(loaded.episodes, episodes, strict=True):
        assert got.observations.shape == (101, 11) and got.actions.shape == (100, 3)
        assert got.observations.dtype == np.float32  # float32 loses nothing here
        np.testing.assert_array_equal(got.observations, want.observations.astype(np.float32))
    # Deterministic: the same seed gives the same demo.
    again = collect_demos(expert, 1, tmp_path / "again.npz", skip_falls=False)
    np.testing.assert_array_equal(again[0].observations, episodes[0].observations)
    card = write_card(out, note="a tiny test expert")
    assert card["note"] == "a tiny test expert"
    assert card["num_demos"] == 2 and card["steps_trained"] >= 400
    assert card["return_mean"] == pytest.approx(np.mean([e.task_score for e in episodes]))
    assert card["paper_expert_return"] == 3420.0
    assert card["fraction_of_paper_expert"] == pytest.approx(card["return_mean"] / 3420, abs=1e-3)
    assert set(card["sha256"]) == {"policy.msgpack", "expert.json", "demos.npz"}
    assert card["demo_seeds_with_a_fall"] == [0, 1]  # kept falls are on the card
    assert card["eval_episodes"] == 10 and card["eval_first_seed"] == 1000
    evaluation = evaluate_expert(out, 10)  # seeds 1000-1009: not the demos'
    assert card["eval_return_mean"] == pytest.approx(evaluation["return_mean"])
    assert card["eval_return_std"] == pytest.approx(evaluation["return_std"])
    result = evaluate_expert(out, 2)
    assert result["episodes"] == 2 and np.isfinite(result["return_mean"])
    latest = export_expert(tiny_run, tmp_path / "latest", which="latest")
    assert json.loads((latest / "expert.json").read_text())["exported"]["policy"] == "latest"
    no_best = tmp_path / "no-best"
    shutil.copytree(tiny_run, no_best)
    (no_best / "best_policy.json").unlink()
    with pytest.warns(UserWarning, match="exporting its latest checkpoint's policy"):
        fallback = export_expert(no_best, tmp_path / "fallback")
    assert json.loads((fallback / "expert.json").read_text())["exported"]["policy"] == "latest"
    assert json.loads((out / "expert.json").read_text())["exported"]["policy"] == "best"


@pytest.mark.integration
def test_expert_cli_train_resume_export_eval(tmp_path, capsys):
    run = tmp_path / "run"
    base = ["expert", "train", "Hopper-v5", "--run-dir", str(run), "--no-progress"]
    first = ["--steps", "150", "--eval-every", "100", "--eval-episodes", "1", "--reward-scale", "2"]
    assert main([*base, *first, "--gamma", "1.5"]) == 2
    assert "--gamma must be in (0, 1)" in capsys.readouterr().err
    assert main([*base, *first, "--healthy-angle-range", "-0.15", "0.15", "--gamma", "0.995"]) == 0
    config = json.loads((run / "config.json").read_text())
    assert (config["eval_every"], config["eval_episodes"]) == (100, 1)
    assert config["sac"]["reward_scale"] == 2.0 and config["sac"]["gamma"] == 0.995
    assert config["healthy_angle_range"] == [-0.15, 0.15]
    assert main([*base, "--steps", "150"]) == 2  # exists: must say --resume
    assert "--resume" in capsys.readouterr().err
    assert main([*base, "--resume", "--reward-scale", "3"]) == 2
    assert "--reward-scale cannot change on --resume" in capsys.readouterr().err
    assert main([*base, "--resume", "--healthy-angle-range", "-0.2", "0.2"]) == 2
    assert "--healthy-angle-range cannot change on --resume" in capsys.readouterr().err
    assert main([*base, "--resume", "--gamma", "0.99"]) == 2
    assert "--gamma cannot change on --resume" in capsys.readouterr().err
    assert main([*base, "--resume", "--no-contact-forces"]) == 2
    assert "--contact-forces cannot change on --resume" in capsys.readouterr().err
    for flag in ("--eval-every", "--eval-episodes", "--checkpoint-every"):  # were ignored
        assert main([*base, "--resume", flag, "5"]) == 2
        assert f"{flag} cannot change on --resume" in capsys.readouterr().err
    assert main([*base[:-2], str(tmp_path / "cf"), "--no-progress", "--no-contact-forces"]) == 2
    assert "--no-contact-forces applies to Ant-v5, Humanoid-v5, not Hopper-v5" in (
        capsys.readouterr().err
    )
    walker = ["expert", "train", "Walker2d-v5", "--run-dir", str(run), "--no-progress"]
    assert main([*walker, "--resume"]) == 2
    assert "trains an expert for Hopper-v5, not Walker2d-v5" in capsys.readouterr().err
    assert main([*base, "--steps", "300", "--resume"]) == 0
    steps = [int(r.split(",")[0]) for r in (run / "metrics.csv").read_text().splitlines()[1:]]
    assert steps == sorted(steps) and steps[-1] >= 300
    assert json.loads((run / "config.json").read_text())["best_by"] == "return"
    evals = [r for r in _metric_rows(run) if r["eval_return"]]
    best = json.loads((run / "best_policy.json").read_text())
    assert len(evals) >= 3
    assert best["eval_return"] == max(float(r["eval_return"]) for r in evals)
    out = tmp_path / "expert"
    export = ["expert", "export", str(run), "--out", str(out), "-n", "1"]
    assert main(export) == 2  # a 300-step expert falls in every episode: no demo
    assert "the expert fell in 3 of 3 episodes" in capsys.readouterr().err
    assert not out.exists()  # all or nothing: no half-written expert directory
    assert main([*export, "--keep-falls", "--note", "falls: the best reached"]) == 0
    assert "kept demos with a fall (seeds [0])" in capsys.readouterr().out
    files = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main(export) == 2  # fails again: the expert exported above stays as it was
    work = tmp_path / "work"
    work.mkdir()
    (work / "mine.txt").write_text("keep me")
    assert main(["expert", "export", str(run), "--out", str(work), "--keep-falls", "-n", "1"]) == 1
    assert "holds other files than an expert's (mine.txt)" in capsys.readouterr().err
    assert [p.name for p in work.iterdir()] == ["mine.txt"]  # nothing deleted
    assert {p.name: p.read_bytes() for p in out.iterdir()} == files
    card = json.loads((out / "card.json").read_text())
    assert card["num_demos"] == 1 and card["demo_seeds"] == [0]
    assert card["note"] == "falls: the best reached" and card["demo_seeds_with_a_fall"] == [0]
    assert card["trained_healthy_angle_range"] == [-0.15, 0.15]
    assert card["observes_contact_forces"] is None  # Hopper has none
    capsys.readouterr()
    assert main(["expert", "eval", str(out), "--episodes", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 1
    collected = tmp_path / "collected.npz"
    collect = ["demos", "collect", "--expert", str(out), "-n", "2", "--out", str(collected)]
    assert main([*collect, "--keep-falls"]) == 0
    assert len(demos.load(collected).episodes) == 2
    assert main([*collect, "--keep-falls"]) == 2  # not over an existing file without --force
    assert "exists: pass --force" in capsys.readouterr().err
    assert main([*collect, "--keep-falls", "-n", "1", "--force"]) == 0
    assert len(demos.load(collected).episodes) == 1
    assert main([*collect[:-1], str(tmp_path / "demos.txt"), "--keep-falls"]) == 2
    assert "must be a .npz file" in capsys.readouterr().err
    assert (
        main(
            [
                "demos",
                "collect",
                "--expert",
                str(out),
                "--env",
                "Walker2d-v5",
                "--out",
                str(collected),
            ]
        )
        == 2
    )
    assert "not Walker2d-v5" in capsys.readouterr().err


@pytest.mark.integration
def test_demos_where_the_expert_falls_are_skipped_and_recorded(tiny_run, tmp_path, monkeypatch):
    from ilfo.experts import ExpertPolicy

    expert = load_expert(export_expert(tiny_run, tmp_path / "Hopper-v5"))
    real = expert.rollout(seed=0)

    def rollout(self, seed):  # the expert falls on odd seeds only
        return real._replace(env_terminated=np.full(len(real.rewards), seed % 2 == 1))

    monkeypatch.setattr(ExpertPolicy, "rollout", rollout)
    episodes = collect_demos(expert, 3, tmp_path / "d.npz", first_seed=10)
    assert len(episodes) == 3
    provenance = demos.load(tmp_path / "d.npz").provenance
    assert provenance["seeds"] == [10, 12, 14]
    assert provenance["skipped_seeds_with_a_fall"] == [11, 13]
    assert provenance["kept_seeds_with_a_fall"] == []
    kept_all = collect_demos(expert, 3, tmp_path / "k.npz", first_seed=10, skip_falls=False)
    kept_provenance = demos.load(tmp_path / "k.npz").provenance
    assert len(kept_all) == 3 and kept_provenance["seeds"] == [10, 11, 12]
    assert kept_provenance["kept_seeds_with_a_fall"] == [11]  # kept, but the card must say so
    with pytest.warns(UserWarning, match=r"seeds \(1000-1002\) reach the expert evaluations"):
        collect_demos(expert, 2, tmp_path / "late.npz", first_seed=999)  # 999 skipped, a fall


@pytest.mark.integration
def test_a_finish_is_kept_at_full_length_and_scored_as_the_evaluation(
    tiny_run, tmp_path, monkeypatch
):
    import ilfo.experts
    from ilfo.experts import ExpertPolicy

    expert = load_expert(export_expert(tiny_run, tmp_path / "Hopper-v5"))
    real = expert.rollout(seed=0)

    def rollout(self, seed):  # terminates from step 40 on: a finish on even seeds, a fall on odd
        rewards = np.ones_like(real.rewards)
        rewards[40] = -100.0 if seed % 2 else 0.5
        return real._replace(rewards=rewards, env_terminated=np.arange(len(rewards)) >= 40)

    monkeypatch.setattr(ExpertPolicy, "rollout", rollout)
    monkeypatch.setattr(ilfo.experts, "termination_is_finish", lambda env, r: r != -100.0)
    collect_demos(expert, 2, tmp_path / "d.npz", first_seed=0)
    loaded = demos.load(tmp_path / "d.npz")
    assert loaded.provenance["skipped_seeds_with_a_fall"] == [1]
    for e in loaded.episodes:  # full length, terminations recorded, scored as evaluated
        assert len(e.observations) == 101 and e.terminated.dtype == bool
        np.testing.assert_array_equal(e.terminated, np.arange(100) >= 40)
        assert e.task_return == pytest.approx(99.5) and e.task_score == pytest.approx(40.0)
    assert demos.summarize(loaded)["return_mean"] == pytest.approx(40.0)
    # --keep-falls keeps a fall
    kept = collect_demos(expert, 2, tmp_path / "k.npz", first_seed=1, skip_falls=False)
    assert [e.task_score for e in kept] == [40.0, 40.0]


@pytest.mark.integration
def test_an_expert_without_contact_forces_records_demos_of_the_full_observation(tmp_path):
    # Ant's expert may learn without the contact forces (as on the paper's v2 Ant, where they
    # were all zero); its demos must still hold all 105 columns, and its actions must be those
    # of the policy on the 27 it observes.
    from ilfo.envs import make_env
    from ilfo.experiments.calibration import calibrate
    from ilfo.training import rollout_policy

    config = dataclasses.replace(
        TINY_SAC, env="Ant-v5", contact_forces=False, steps=250, horizon=30, eval_every=250
    )
    run = tmp_path / "run"
    Trainer(config, run, progress=False).train()
    expert = load_expert(export_expert(run, tmp_path / "Ant-v5"))
    assert not expert.sees_all_columns
    out = tmp_path / "Ant-v5"
    (episode,) = collect_demos(expert, 1, out / DEMOS_FILE, first_seed=3, skip_falls=False)
    assert episode.observations.shape == (31, 105)
    narrow = rollout_policy(
        make_env("Ant-v5", True, horizon=30, contact_forces=False),
        expert.agent,
        expert.policy,
        30,
        seed=3,
    )
    np.testing.assert_array_equal(episode.observations[:, :27], narrow.observations)
    np.testing.assert_allclose(episode.actions, narrow.actions, rtol=1e-5, atol=1e-6)
    assert np.abs(episode.observations[:, 27:]).max() > 0  # the contact forces, recorded
    assert write_card(out)["observes_contact_forces"] is False
    np.testing.assert_array_equal(expert.observe(episode.observations), narrow.observations)
    for contact_forces in (None, True):  # the reward with or without them; the expert acts
        points = calibrate(
            "Ant-v5",
            (0.0,),
            episodes=1,
            expert_directory=out,
            horizon=20,
            contact_forces=contact_forces,
        )
        assert len(points) == 3 and all(np.isfinite(p.ot_distance) for p in points)


def test_missing_expert_is_a_clear_error(tmp_path, capsys):
    with pytest.raises(FileNotFoundError, match="no expert"):
        load_expert(tmp_path)
    assert main(["expert", "eval", "NoSuchEnv-v0"]) == 2
    assert "no expert" in capsys.readouterr().err


@pytest.mark.parametrize("episodes", [0, 10_001, 10**9, 2.5])
def test_expert_eval_episodes_are_bounded_as_a_runs_evaluation(episodes, capsys, monkeypatch):
    """Checked before the expert is loaded (a billion episodes' seeds alone are GBs)."""
    import ilfo.experts

    def unreachable(path):
        raise AssertionError("the expert was loaded before its episodes were checked")

    monkeypatch.setattr(ilfo.experts, "load_expert", unreachable)
    with pytest.raises(ValueError, match="episodes must be"):
        evaluate_expert("Hopper-v5", episodes)
    if isinstance(episodes, int):
        assert main(["expert", "eval", "Hopper-v5", "--episodes", str(episodes)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "--episodes must be from 1 to 10,000" in err, err
