import json
import os
import signal

import numpy as np
import pytest

from ilfo.cli import main
from ilfo.paths import bundled_demos


def test_reward_demo_on_bundled_data_ranks_learners(capsys):
    assert main(["reward", "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(rows) == 3 and all(r["converged"] for r in rows)
    noisy, same_policy, random_policy = (r["ot_distance"] for r in rows)
    # The noisy copy of the demo is closest, the random-action episode farthest.
    assert noisy < same_policy < random_policy


def test_reward_on_a_two_episode_file_scores_the_other_episode_once(capsys, tmp_path):
    from ilfo import demos

    rng = np.random.default_rng(0)
    path = tmp_path / "two.npz"
    demos.save(path, [demos.Episode(rng.normal(size=(11, 11))) for _ in range(2)], "Hopper-v5")
    assert main(["reward", "--json", "--demos", str(path)]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["learner"] for r in rows] == ["expert + N(0, 0.01^2) noise", "episode 1"]


def test_reward_with_every_solver_and_pwil(capsys):
    """Each flag reaches the reward: the rows are the library's numbers for those settings."""
    from ilfo import demos
    from ilfo.rewards import OOPS, PWIL, OOPSConfig

    episodes = [e.observations for e in demos.load(bundled_demos("Hopper-v5-scripted")).episodes]
    expert, learner = episodes[0], episodes[1]
    rewarders = {
        "emd": OOPS([expert], OOPSConfig(solver="emd")),
        "greedy": OOPS([expert], OOPSConfig(solver="greedy")),
        "pwil": PWIL([expert]),
    }
    rows = {}
    for name, extra in (
        ("emd", ["--solver", "emd"]),
        ("greedy", ["--solver", "greedy"]),
        ("pwil", ["--rewarder", "pwil"]),
    ):
        assert main(["reward", "--json", "--learners", "1", *extra]) == 0
        rows[name] = json.loads(capsys.readouterr().out)
        want = rewarders[name](learner)
        assert rows[name]["ot_distance"] == pytest.approx(want.distance, rel=1e-9)
        assert rows[name]["mean_reward"] == pytest.approx(float(want.rewards.mean()), rel=1e-9)
    assert rows["greedy"]["ot_distance"] >= rows["emd"]["ot_distance"]  # exact is the least
    assert 0 < rows["pwil"]["mean_reward"] <= 5  # PWIL's exp(-distance) scale, 5 at most


def test_reward_errors_are_clear(capsys, tmp_path):
    assert main(["reward", "--demos", str(tmp_path / "none.npz")]) == 2
    assert "no demonstration file" in capsys.readouterr().err
    assert main(["reward", "--expert", "99"]) == 2
    assert "out of range" in capsys.readouterr().err
    assert main(["reward", "--rewarder", "pwil", "--solver", "emd", "--reg", "0.1"]) == 2
    assert "--solver, --reg: OOPS settings" in capsys.readouterr().err


def test_reward_scores_ant_demos_without_contact_forces_by_default(capsys, tmp_path):
    """As `ilfo train` imitates Ant-v5: the 78 contact-force columns that end its observations
    are left out unless asked for, so two episodes that differ only there are at distance 0."""
    from ilfo import demos
    from ilfo.envs import CONTACT_FORCE_DIMS

    rng = np.random.default_rng(0)
    body = rng.normal(size=(21, 27))
    forces = np.zeros((21, CONTACT_FORCE_DIMS["Ant-v5"]))
    expert = demos.Episode(np.hstack([body, forces]))
    learner = demos.Episode(np.hstack([body, forces + 5.0]))
    path = tmp_path / "ant.npz"
    demos.save(path, [expert, learner], "Ant-v5")

    distances = {}
    for flag in ([], ["--no-contact-forces"], ["--contact-forces"]):
        assert main(["reward", "--json", "--demos", str(path), "--learners", "1", *flag]) == 0
        distances[tuple(flag)] = json.loads(capsys.readouterr().out)["ot_distance"]
    assert distances[()] == distances[("--no-contact-forces",)] < 1e-3
    assert distances[("--contact-forces",)] > 1.0
    # A file already without them (27 columns) is scored as it is, not cut again.
    narrow = tmp_path / "ant27.npz"
    demos.save(narrow, [demos.Episode(body), demos.Episode(body + 1.0)], "Ant-v5")
    assert main(["reward", "--json", "--demos", str(narrow), "--learners", "1"]) == 0
    assert json.loads(capsys.readouterr().out)["ot_distance"] > 1.0

    assert main(["reward", "--no-contact-forces"]) == 2  # Hopper has none
    assert "applies to" in capsys.readouterr().err


def test_bundled_demos_are_found():
    assert bundled_demos("Hopper-v5-scripted").is_file()


def test_stop_signals_interrupt_even_where_sigint_was_ignored():
    """A sweep started in the background by a script has SIGINT ignored; `kill PID` sends
    SIGTERM. Both must reach the sweep's checkpoint-and-stop path (KeyboardInterrupt)."""
    from ilfo.cli._common import stop_signals_interrupt

    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            with pytest.raises(KeyboardInterrupt), stop_signals_interrupt():
                os.kill(os.getpid(), sig)
                signal.sigtimedwait([], 1.0)  # give the handler its moment
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN  # restored on the way out
    finally:
        signal.signal(signal.SIGINT, before)


def test_a_bad_flag_is_not_buried_under_the_full_usage(capsys, tmp_path):
    with pytest.raises(SystemExit) as stopped:
        main(["train", "--algo", "nope"])
    assert stopped.value.code == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "usage: ilfo train [options]  (all of them: ilfo train --help)"
    assert "invalid choice: 'nope'" in err[1] and len(err) == 2
    with pytest.raises(SystemExit):  # a sweep's train flags: the help is `ilfo train`'s
        main(["sweep", "run", str(tmp_path / "s"), "--env", "Hopper-v5", "--steps", "abc"])
    assert "(all of them: ilfo train --help)" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
    with pytest.raises(SystemExit):  # a short usage is shown as it is
        main(["demos", "info"])
    assert capsys.readouterr().err.startswith("usage: ilfo demos info [-h] [--json] file")


def test_a_missing_optional_dependency_is_a_one_line_error(monkeypatch, capsys):
    def needs_pybullet(args):
        raise ImportError('PyBullet is not installed: pip install -e ".[bullet]"')

    monkeypatch.setattr("ilfo.cli.data._run_reward", needs_pybullet)
    assert main(["reward"]) == 1
    err = capsys.readouterr().err
    assert err == 'ilfo: error: PyBullet is not installed: pip install -e ".[bullet]"\n'


def test_demos_collect_refuses_a_negative_seed(tmp_path, capsys):
    out = tmp_path / "d.npz"
    args = ["demos", "collect", "--expert", "Hopper-v5", "-n", "1", "--seed", "-1"]
    assert main([*args, "--out", str(out)]) == 2
    assert "seeds must be >= 0, got -1" in capsys.readouterr().err and not out.exists()


@pytest.mark.integration
def test_an_accelerator_jax_cannot_start_is_a_clear_error():
    # Without a CUDA build of JAX, JAX_PLATFORMS=cuda ends in a bare AssertionError inside JAX.
    import os
    import subprocess
    import sys

    env = {**os.environ, "JAX_PLATFORMS": "cuda"}
    done = subprocess.run(
        [sys.executable, "-m", "ilfo.cli", "reward"], env=env, capture_output=True, text=True
    )
    assert done.returncode == 2, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("ilfo: error: JAX_PLATFORMS=cuda: JAX cannot start 'cuda'")
    assert "unset JAX_PLATFORMS" in last and "Traceback" not in done.stderr


def test_train_starts_by_saying_what_it_trains_and_for_how_long():
    """The start summary names the algo, env, preset, seed, demo file and count, steps and the
    run directory; the expected duration comes from the measured rates (shorter for a run
    resumed near its end; none for an algo without a measured rate)."""
    from pathlib import Path

    from ilfo.cli.train import start_summary
    from ilfo.training import DemoSource, TrainConfig

    demos = DemoSource("/data/experts/Walker2d-v5/demos.npz", "0" * 64, 4, 4000.0)
    config = TrainConfig(env="Walker2d-v5", num_demos=4, seed=3, steps=300_000, preset="fast")
    run_dir = Path("runs/Walker2d-v5__oops-td3__3__20261207-120000")
    text = start_summary(config, run_dir, demos)
    lines = text.splitlines()
    assert lines[0] == "oops-td3 on Walker2d-v5, fast preset, seed 3"
    assert "  demos: /data/experts/Walker2d-v5/demos.npz (its first 4 demos)" in lines
    assert "  steps: 300,000; evaluated every 5,000" in lines
    assert lines[-1] == f"  writes: {run_dir}"

    def expected_seconds(summary):
        (line,) = [line for line in summary.splitlines() if line.startswith("  expected: ~")]
        value, unit = line.removeprefix("  expected: ~").split()[:2]
        return float(value) * {"s": 1, "min": 60, "h": 3600}[unit]

    late = start_summary(config, run_dir, demos, step=290_000)
    assert "  steps: 300,000, from step 290,000; evaluated every 5,000" in late.splitlines()
    assert 0 < expected_seconds(late) < expected_seconds(text) / 5
    from ilfo.algos import ALGOS
    from ilfo.experiments.estimates import measured_rates

    task_reward = [a for a in ALGOS if ALGOS[a].reward is None and a not in measured_rates()]
    unmeasured = start_summary(TrainConfig(algo=task_reward[0]), run_dir, None)
    assert f"demos: none ({task_reward[0]} learns from the task reward)" in unmeasured
    assert "expected" not in unmeasured


def test_train_help_opens_with_the_common_options(capsys):
    """`ilfo train --help` lists hundreds of options; its first screen names the common ones
    and says where the rest are."""
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    top = capsys.readouterr().out.splitlines()[:40]
    common = ["--env", "--algo", "--demos", "--num-demos", "--steps", "--preset", "--seed"]
    common += ["--out", "--resume", "--config"]
    for flag in common:
        assert any(line.startswith(f"  {flag} ") for line in top), flag
    from ilfo.training import TrainConfig

    (steps,) = [line for line in top if line.startswith("  --steps N ")]
    assert steps.endswith(f"(default {TrainConfig().steps:,})")  # read off the config
    assert any("grouped by part" in line for line in top)
