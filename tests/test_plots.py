"""`ilfo plot`'s curves: runs trained otherwise are separate curves, labelled by how."""

from __future__ import annotations

import csv
import dataclasses
import json

import pytest

from ilfo.rewards.oops import OOPSConfig
from ilfo.training import TrainConfig
from ilfo.training.plots import curve_groups, plot_runs


def _run(root, name, scores, **settings):
    """A run directory with its config as the trainer writes it and one evaluation per score."""
    run = root / name
    run.mkdir()
    config = TrainConfig(**{"env": "Hopper-v5", **settings}).resolved(1000)
    (run / "config.json").write_text(json.dumps(dataclasses.asdict(config)))
    with (run / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["step", "episode", "eval_score", "eval_score_norm"])
        for k, score in enumerate(scores):
            writer.writerow([1000 * (k + 1), k + 1, 100 * score, score])
    return run


def test_runs_of_different_settings_are_separate_curves_named_by_their_settings(tmp_path):
    paper = [_run(tmp_path, f"paper{s}", [0.1, 0.2], seed=s) for s in (0, 1)]
    fast = _run(tmp_path, "fast", [0.5, 0.9], preset="fast")
    other_task = _run(tmp_path, "walker", [0.3, 0.4], env="Walker2d-v5", preset="fast")
    metric, groups = curve_groups([*paper, fast, other_task])
    assert metric == "eval_score_norm"
    assert {label: len(curves) for label, curves in groups.items()} == {
        "Hopper-v5 oops-td3, 1 demo, defaults": 2,
        "Hopper-v5 oops-td3, 1 demo, fast preset": 1,
        # Alone on its task: nothing to tell it from, so its label stays short.
        "Walker2d-v5 oops-td3, 1 demo": 1,
    }
    assert groups["Hopper-v5 oops-td3, 1 demo, fast preset"][0][1].tolist() == [0.5, 0.9]
    out = plot_runs([*paper, fast], tmp_path / "curves.png")
    assert out.stat().st_size > 0


def test_runs_of_other_demos_or_reward_settings_are_not_seeds_of_one_curve(tmp_path):
    one = _run(tmp_path, "one", [0.1], seed=0)
    four = _run(tmp_path, "four", [0.2], seed=1, num_demos=4)
    reward = _run(tmp_path, "reward", [0.3], seed=2, oops=OOPSConfig(reg=0.1))
    _, groups = curve_groups([one, four, reward])
    assert sorted(groups) == [
        "Hopper-v5 oops-td3 [oops.reg=0.1], 1 demo",
        "Hopper-v5 oops-td3, 1 demo",
        "Hopper-v5 oops-td3, 4 demos",
    ]


def test_a_config_that_names_no_env_is_refused_naming_the_file(tmp_path):
    run = _run(tmp_path, "r", [0.1])
    (run / "config.json").write_text(json.dumps({"algo": "oops-td3"}))
    with pytest.raises(ValueError, match=r"r/config.json names no env and algo"):
        curve_groups([run])
