"""The migrations (``training.migrations``): run records of every older format read as today's,
and older runs evaluate, export and resume exactly.

A fixture per older format of a run directory, each a tiny OOPS+TD3 run (Hopper-v5, horizon
100, 16-unit networks, OOPS warm starts) with the metrics of the same command run
uninterrupted to 600 steps by the same code:

- ``fixtures/run_2eddc1d``, written at commit 2eddc1d (2026-11-24), stopped at 400 steps:
  config.json unversioned and without ``contact_forces``, no ``demos.json``; its checkpoint of
  format 1 as first written (the reward's state as ``rewarder_rng`` and
  ``rewarder_potentials.npz``, a ``latest`` pointer beside it, no copy of the best policy).
- ``fixtures/run_446cbed``, written at commit 446cbed (2026-12-07, the last before formats
  were numbered in config.json), stopped at 200 steps inside its 300-step random phase:
  config.json unversioned with every setting resolved, ``demos.json``; its checkpoint of format
  1 as last written (``reward_state``, ``reward_arrays.npz``, ``random_states.npz``, the best
  policy's copy, the loop's counters at the top of state.json).

Records of the other older shapes (a PWIL-(s) run's unresolved episodes, a task-reward run's
demos) are written in the tests.
"""

import csv
import dataclasses
import json
import shutil
from pathlib import Path

import pytest

from ilfo.cli import main
from ilfo.evaluate import evaluate_run
from ilfo.paths import bundled_demos
from ilfo.training import TrainConfig, Trainer, config_from_dict, load_run_policy, migrations
from ilfo.training.migrations import (
    CHECKPOINT_FORMAT,
    CONFIG_FORMAT,
    config_record,
    read_run_config,
    upgrade_checkpoint_state,
    upgrade_run_config,
    upgrade_sweep_run_config,
)
from ilfo.training.run_dir import latest_checkpoint
from tiny_run import metrics_rows

pytestmark = pytest.mark.integration  # each test resumes a run

FIXTURES = Path(__file__).parent / "fixtures"
DEMOS = str(bundled_demos("Hopper-v5-scripted"))


def _old_run(tmp_path: Path, name: str) -> Path:
    run = tmp_path / name
    shutil.copytree(FIXTURES / name, run)
    config = json.loads((run / "config.json").read_text())
    config["demos"] = DEMOS  # where this checkout has them
    (run / "config.json").write_text(json.dumps(config, indent=2))
    return run


def _reference_rows(name: str) -> list[dict[str, str]]:
    with (FIXTURES / f"{name}_metrics_to_600.csv").open() as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        row.pop("wall_time"), row.pop("steps_per_s")
    return rows


def _state(checkpoint: Path) -> dict:
    return json.loads((checkpoint / "state.json").read_text())


def test_a_run_of_2eddc1d_evaluates_and_resumes_to_its_uninterrupted_numbers(tmp_path, capsys):
    run = _old_run(tmp_path, "run_2eddc1d")
    latest = load_run_policy(run, "latest").checkpoint
    assert latest is not None and latest.loop.step == 400 and latest.loop.best_eval["step"] == 200
    assert set(latest.reward_state.values) == {"rng"} and latest.reward_state.arrays
    assert read_run_config(run)["contact_forces"] is True  # it observed them: no setting yet
    result = evaluate_run(run, episodes=1)
    assert result["policy"] == "policy.msgpack" and result["episodes"] == 1
    assert main(["eval", str(run), "--best", "--episodes", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["policy"] == "best_policy.msgpack"

    trainer = Trainer.resume(run, progress=False, steps=600)
    assert trainer.step == 400
    # The run directory is today's now: its config's format, its demos recorded from the step
    # it resumed at, the old pointer gone (the checkpoint stays until the next replaces it).
    assert json.loads((run / "config.json").read_text())["format"] == CONFIG_FORMAT
    assert json.loads((run / "demos.json").read_text())["since_step"] == 400
    assert not (run / "checkpoints" / "latest").exists()
    resumed = metrics_rows(trainer.train())
    reference = _reference_rows("run_2eddc1d")
    # Columns added since (learned rewards' metrics) stay empty for this algo.
    added = set(resumed[0]) - set(reference[0])
    assert added and all(row[k] == "" for row in resumed for k in added)
    assert [{k: row[k] for k in reference[0]} for row in resumed] == reference
    assert _state(latest_checkpoint(run))["schema"] == CHECKPOINT_FORMAT


def test_a_run_of_446cbed_resumes_to_its_uninterrupted_numbers(tmp_path, monkeypatch):
    run = _old_run(tmp_path, "run_446cbed")
    before = _state(latest_checkpoint(run))
    assert before["schema"] == 1 and "loop" not in before
    latest = load_run_policy(run, "latest").checkpoint
    assert latest is not None and latest.loop.step == 200 and latest.loop.random_states
    assert latest.loop.best_eval["step"] == 200 and latest.reward_state.arrays

    trainer = Trainer.resume(run, progress=False, steps=600)
    assert (trainer.step, trainer.episode, len(trainer.loop_state.random_states)) == (200, 2, 2)
    assert metrics_rows(trainer.train()) == _reference_rows("run_446cbed")
    state = _state(latest_checkpoint(run))
    assert state["schema"] == CHECKPOINT_FORMAT and state["loop"]["step"] == 600

    # Today's format goes through no migration step: with none left, the run still reads.
    monkeypatch.setattr(migrations, "_RUN_CONFIG_STEPS", {})
    monkeypatch.setattr(migrations, "_CHECKPOINT_STEPS", {})
    assert config_from_dict(read_run_config(run), "config.json").steps == 600
    again = Trainer.resume(run, progress=False)
    again._lock.release()
    assert load_run_policy(run, "latest").checkpoint.loop == again.loop_state


def test_a_config_record_without_contact_forces_reads_as_observing_them():
    record = {"env": "Ant-v5", "algo": "oops-td3", "steps": 1000}
    assert upgrade_run_config(record, "config.json")["contact_forces"] is True
    assert upgrade_sweep_run_config(record, "sweep.json")["contact_forces"] is True
    given = {**record, "contact_forces": None}  # recorded: as it says (the algo's default)
    assert upgrade_run_config(given, "config.json")["contact_forces"] is None


def test_pwils_older_runs_read_as_the_fixed_horizon_they_ran(tmp_path):
    """A config.json from before records held the resolved episodes says None: a PWIL-(s) run
    then trained on the fixed horizon, and resumes and reports so. A sweep's manifest holds
    its settings unresolved: there None is the algo's default (standard episodes)."""
    for algo, as_run in (("pwil-td3", True), ("oops-td3", None), ("firl-fkl", None)):
        record = {**dataclasses.asdict(TrainConfig(algo=algo)), "fixed_horizon": None}
        run = tmp_path / algo
        run.mkdir()
        (run / "config.json").write_text(json.dumps(record))
        assert read_run_config(run)["fixed_horizon"] is as_run
        assert upgrade_sweep_run_config(record, "sweep.json")["fixed_horizon"] is None
    old_pwil = config_from_dict(read_run_config(tmp_path / "pwil-td3"), "config.json")
    assert old_pwil.uses_fixed_horizon and old_pwil.agent_config(1000).time_augmentation
    recorded = config_record(dataclasses.asdict(TrainConfig(algo="pwil-td3").resolved(1000)))
    (tmp_path / "pwil-td3" / "config.json").write_text(json.dumps(recorded))
    assert read_run_config(tmp_path / "pwil-td3")["fixed_horizon"] is False  # as recorded


def test_a_run_given_as_settings_repeats_the_episodes_it_ran(tmp_path):
    """`--config RUN/config.json` repeats an old PWIL-(s) run on the fixed horizon it ran; the
    same settings in a file outside a run directory are a user's settings, whose None means
    the algo's default (standard episodes)."""
    from ilfo.cli.train import config_from_args

    record = {**dataclasses.asdict(TrainConfig(algo="pwil-td3")), "fixed_horizon": None}
    run, loose = tmp_path / "run", tmp_path / "mine"
    for folder in (run, loose):
        folder.mkdir()
        (folder / "config.json").write_text(json.dumps(record))
    (run / "metrics.csv").write_text("step,episode\n")
    repeat = config_from_args(str(run / "config.json"), {}, {})
    assert repeat.uses_fixed_horizon
    assert not config_from_args(
        str(run / "config.json"), {"fixed_horizon": False}, {}
    ).uses_fixed_horizon
    assert not config_from_args(str(loose / "config.json"), {}, {}).uses_fixed_horizon


def test_a_task_reward_record_with_demos_reads_back_without_them():
    """Records from before demos were refused for the task reward (they were ignored)."""
    record = {**dataclasses.asdict(TrainConfig(algo="td3")), "demos": DEMOS}
    assert "demos" not in upgrade_run_config(record, "config.json")
    assert "demos" not in upgrade_sweep_run_config(record, "sweep.json")
    with pytest.raises(ValueError, match="do not apply to algo 'td3'"):
        config_from_dict(record, "config.json")
    imitation = {**dataclasses.asdict(TrainConfig()), "demos": DEMOS}
    assert upgrade_run_config(imitation, "config.json")["demos"] == DEMOS


def test_a_td7_record_of_format_1_reads_without_policy_checkpoints():
    """TD7 evaluated the policy as trained before its policy checkpoints (format 2, on by
    default): its older records, and a sweep's runs left to the preset, read with them off."""
    from ilfo.agents.td7 import TD7Config

    for algo in ("td7", "oops-td7"):
        record = {**dataclasses.asdict(TrainConfig(algo=algo).resolved(1000)), "format": 1}
        del record["td7"]["policy_checkpoints"]
        assert not config_from_dict(upgrade_run_config(record, "c"), "c").td7.policy_checkpoints
        sweep_run = {**dataclasses.asdict(TrainConfig(algo=algo, preset="fast")), "format": 1}
        sweep_td7 = config_from_dict(upgrade_sweep_run_config(sweep_run, "s"), "s").td7
        assert sweep_td7 == TD7Config.fast(policy_checkpoints=False)
    today = config_record(dataclasses.asdict(TrainConfig(algo="td7")))
    assert (
        config_from_dict(upgrade_run_config(today, "c"), "c").part_config("td7").policy_checkpoints
    )
    td3 = {**dataclasses.asdict(TrainConfig(algo="td3")), "format": 1}
    assert upgrade_run_config(td3, "c") == {k: v for k, v in td3.items() if k != "format"}


def test_records_of_todays_format_read_back_as_written_and_newer_ones_are_refused():
    settings = dataclasses.asdict(TrainConfig(algo="pwil-td3"))  # fixed_horizon None
    record = config_record(settings)
    assert record["format"] == CONFIG_FORMAT
    assert upgrade_run_config(record, "config.json") == settings  # no step: None stays
    newer = CONFIG_FORMAT + 1
    with pytest.raises(ValueError, match=rf"config.json: format {newer}, not one this ilfo reads"):
        upgrade_run_config({**settings, "format": CONFIG_FORMAT + 1}, "config.json")
    with pytest.raises(ValueError, match=r"state.json: schema 3, not one this ilfo reads"):
        upgrade_checkpoint_state({"schema": CHECKPOINT_FORMAT + 1}, (), "state.json")
    with pytest.raises(ValueError, match=r"state.json: schema None"):
        upgrade_checkpoint_state({"step": 5}, (), "state.json")
