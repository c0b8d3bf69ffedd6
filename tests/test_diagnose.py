"""`ilfo diagnose`: a tiny OOPS run's policy against its demo (shares, rewards, calibration)."""

import dataclasses
import json
import shutil

import numpy as np
import pytest

from ilfo import demos
from ilfo.cli import main
from ilfo.diagnose import (
    REPORT_FILE,
    cost_by_column,
    diagnose_episodes,
    diagnose_run,
    expert_calibration,
    noisy_demo_copies,
)
from ilfo.evaluate import evaluate_run
from ilfo.paths import bundled_demos
from ilfo.rewards import OOPS, OOPSConfig
from ilfo.training import TrainConfig, Trainer, default_demos_path, load_demo_set, make_reward
from tiny_run import TINY_RUN

DEMOS = TINY_RUN["demos"]
TINY = {**TINY_RUN, "steps": 400}
FIGURES = ("shares.png", "rewards.png", "calibration.png", "trajectories.png")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    path = tmp_path_factory.mktemp("diagnose") / "run"
    return Trainer(TrainConfig(**TINY), path, progress=False).train()


@pytest.fixture(scope="module")
def result(run):
    return diagnose_run(run, episodes=2)


@pytest.mark.integration
def test_the_command_writes_the_report_and_prints_a_summary(run, tmp_path, capsys):
    assert main(["diagnose", str(run), "--out", str(tmp_path / "report")]) == 0
    out = capsys.readouterr().out
    for name in (REPORT_FILE, *FIGURES):
        assert (tmp_path / "report" / name).stat().st_size > 0, name
    assert f"report: {tmp_path / 'report' / REPORT_FILE}" in out
    assert "policy: policy.msgpack, 1 deterministic episode(s) of 100 steps" in out
    assert "top dimensions (share of the transported cost): s[" in out
    text = (tmp_path / "report" / REPORT_FILE).read_text()
    for section in ("## 1.", "## 2.", "## 3.", "## 4.", "| **the learner** |"):
        assert section in text
    # The scripted demos are not the shipped expert's: that part is skipped with a note.
    assert "The shipped expert with action noise: skipped: it is scored against" in text
    assert main(["diagnose", str(run), "--best"]) == 0  # the default --out: RUN/diagnosis
    assert "policy: best_policy.msgpack" in capsys.readouterr().out
    assert (run / "diagnosis" / REPORT_FILE).is_file()


@pytest.mark.integration
def test_shares_are_non_negative_and_sum_to_one(result):
    shares = result.diagnosis.shares
    assert shares.shape == (11,) and (shares >= 0).all()
    assert shares.sum() == pytest.approx(1.0, abs=1e-12)
    assert [shares[k] for k in result.diagnosis.top(3)] == sorted(shares, reverse=True)[:3]
    for e in result.diagnosis.episodes:  # the decomposition accounts for the whole distance
        assert e.column_costs.shape == (22,) and (e.column_costs >= 0).all()
        assert e.column_costs.sum() == pytest.approx(e.distance, rel=1e-9)


@pytest.mark.integration
def test_the_proxy_rewards_are_the_ones_oops_gives_the_episode(run, result):
    config = result.config
    reward = make_reward(config, load_demo_set(config, 11).observations)  # as the run built it
    for e in result.diagnosis.episodes:
        np.testing.assert_array_equal(e.proxy_rewards, reward(e.observations).rewards)
    # The episodes are the run's evaluation episodes, as `ilfo eval` rolls them out.
    evaluated = evaluate_run(run, episodes=2)
    assert np.mean(result.scores) == pytest.approx(evaluated["score_mean"])
    assert result.diagnosis.distance == pytest.approx(evaluated["ot_distance"])
    for e in result.diagnosis.episodes:
        assert len(e.task_rewards) == len(e.proxy_rewards) == 100


def test_cost_by_column_against_the_pairwise_definition():
    rng = np.random.default_rng(3)
    x, y, w = rng.normal(size=(7, 4)), rng.normal(size=(5, 4)), rng.random((7, 5))
    diff2 = (x[:, None, :] - y[None, :, :]) ** 2  # (n, m, k)
    expected = (w[:, :, None] * diff2 / diff2.sum(axis=2, keepdims=True)).sum(axis=(0, 1))
    np.testing.assert_allclose(cost_by_column(x, y, w), expected, rtol=1e-12)
    # With the squared Euclidean cost, the shares are those of sum_ij P_ij (x_ik - y_jk)^2.
    episode, demo = rng.normal(size=(31, 3)), rng.normal(size=(41, 3))
    d = diagnose_episodes([episode], [demo], OOPSConfig(metric="sqeuclidean", standardize=False))
    plan = OOPS([demo], d.config)(episode).coupling.plan
    atoms_x = np.concatenate([episode[:-1], episode[1:]], axis=1)
    atoms_y = np.concatenate([demo[:-1], demo[1:]], axis=1)
    per_column = np.einsum("ij,ijk->k", plan, (atoms_x[:, None] - atoms_y[None]) ** 2)
    per_state = per_column.reshape(2, -1).sum(axis=0)
    np.testing.assert_allclose(d.shares, per_state / per_state.sum(), rtol=1e-9)


def test_the_demo_against_itself_is_near_zero_and_noise_moves_it_away():
    demo = demos.load(DEMOS).episodes[0].observations
    d = diagnose_episodes([demo], [demo], names=[f"x{k}" for k in range(11)])
    assert d.distance < 0.01 and d.episodes[0].demo_index == 0
    assert d.shares.sum() == pytest.approx(1.0) and d.names[0] == "x0"
    copies = noisy_demo_copies(OOPS([demo]), demo, len(demo) - 1, scales=(0.0, 0.1, 1.0))
    assert copies[0].distance == pytest.approx(d.distance)
    assert copies[0].distance < copies[1].distance < copies[2].distance
    # Pooled demos and a time index: one more column, and no single demo matched.
    config = OOPSConfig(demo_selection="pooled", time_index=True)
    pooled = diagnose_episodes([demo[:101]], [demo, demo[::-1]], config)
    assert pooled.shares.shape == (12,) and pooled.names[-1] == "time index"
    assert pooled.shares.sum() == pytest.approx(1.0) and pooled.episodes[0].demo_index is None
    with pytest.raises(ValueError, match="3 names for 11 observation columns"):
        diagnose_episodes([demo], [demo], names=["a", "b", "c"])


@pytest.mark.integration
def test_with_the_shipped_expert_s_demos_the_expert_calibration_is_in_the_report(
    run, tmp_path, capsys
):
    expert_demos = str(default_demos_path("Hopper-v5"))
    out = tmp_path / "report"
    assert main(["diagnose", str(run), "--demos", expert_demos, "--out", str(out)]) == 0
    text = (out / REPORT_FILE).read_text()
    assert f"`{expert_demos}` (one demo)" in text
    assert "| expert + N(0, 0.1^2) |" in text and "| random |" in text
    config = TrainConfig(**TINY)
    points, note = expert_calibration(config, default_demos_path("Hopper-v5"), 1, 30, OOPSConfig())
    assert note is None
    by_policy = {p.policy: p for p in points}
    assert by_policy["expert + N(0, 0.0^2)"].ot_distance < by_policy["random"].ot_distance
    skipped = expert_calibration(config, bundled_demos("Hopper-v5-scripted"), 1, 30, OOPSConfig())
    assert skipped[0] == [] and skipped[1].startswith("skipped: it is scored against the shipped")


def _error(args, capsys):
    assert main(["diagnose", *map(str, args)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ilfo: error: ") and err.count("\n") == 1, err
    return err


@pytest.mark.integration
def test_clear_errors(run, tmp_path, capsys):
    assert "is not a run directory (no config.json)" in _error([tmp_path], capsys)
    td3 = tmp_path / "td3"
    td3.mkdir()
    config = dataclasses.asdict(TrainConfig(env="Hopper-v5", algo="td3", horizon=100))
    (td3 / "config.json").write_text(json.dumps(config))
    err = _error([td3], capsys)
    assert "is a td3 run on the task reward, without demos: diagnose needs an imitation" in err
    bare = tmp_path / "bare"
    bare.mkdir()
    for name in ("config.json", "demos.json"):
        shutil.copy(run / name, bare / name)
    assert "has neither policy.msgpack nor a checkpoint" in _error([bare], capsys)
    assert "has no best_policy.msgpack" in _error([bare, "--best"], capsys)
    narrow = tmp_path / "narrow.npz"
    episode = demos.Episode(np.zeros((11, 5)))
    demos.save(narrow, [episode], "Hopper-v5")
    err = _error([run, "--demos", narrow], capsys)
    assert f"--demos {narrow}: observations of width 5, the run's Hopper-v5 observes 11" in err
    assert "--episodes must be from 1 to" in _error([run, "--episodes", "0"], capsys)
