"""Run directories written by earlier ilfo versions still evaluate, export and resume exactly.

``fixtures/run_2eddc1d`` is a tiny OOPS+TD3 run (Hopper-v5, horizon 100, 16-unit networks, OOPS
warm starts) written by ilfo at commit 2eddc1d (2026-11-24: one ``train.py``, a ``latest``
pointer beside the checkpoint, the reward's state as ``rewarder_rng`` and
``rewarder_potentials.npz``), stopped at 400 steps; ``run_2eddc1d_metrics_to_600.csv`` is the
same command run uninterrupted to 600 steps by the same code.
"""

import csv
import json
import shutil
from pathlib import Path

import pytest

from ilfo.cli import main
from ilfo.evaluate import evaluate_run
from ilfo.paths import bundled_demos
from ilfo.training import Trainer, load_run_policy
from tiny_run import metrics_rows

pytestmark = pytest.mark.integration  # each test resumes a run

FIXTURES = Path(__file__).parent / "fixtures"


def _old_run(tmp_path):
    run = tmp_path / "run"
    shutil.copytree(FIXTURES / "run_2eddc1d", run)
    config = json.loads((run / "config.json").read_text())
    config["demos"] = str(bundled_demos("Hopper-v5-scripted"))  # where this checkout has them
    (run / "config.json").write_text(json.dumps(config, indent=2))
    return run


def test_a_run_of_an_earlier_version_evaluates_and_resumes_to_its_uninterrupted_numbers(
    tmp_path, capsys
):
    run = _old_run(tmp_path)
    assert load_run_policy(run, "latest").checkpoint.step == 400
    result = evaluate_run(run, episodes=1)
    assert result["policy"] == "policy.msgpack" and result["episodes"] == 1
    assert main(["eval", str(run), "--best", "--episodes", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["policy"] == "best_policy.msgpack"

    trainer = Trainer.resume(run, progress=False, steps=600)
    assert trainer.step == 400
    assert not (run / "checkpoints" / "latest").exists()  # the old pointer, not needed now
    resumed = metrics_rows(trainer.train())
    with (FIXTURES / "run_2eddc1d_metrics_to_600.csv").open() as f:
        reference = list(csv.DictReader(f))
    for row in reference:
        row.pop("wall_time"), row.pop("steps_per_s")
    # Columns added since (learned rewards' metrics) stay empty for this algo.
    added = set(resumed[0]) - set(reference[0])
    assert added and all(row[k] == "" for row in resumed for k in added)
    assert [{k: row[k] for k in reference[0]} for row in resumed] == reference
