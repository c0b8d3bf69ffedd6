"""`ilfo reproduce`: every experiment plans at every budget, its variants are the paper's, and
table1's smoke budget runs end to end into a report."""

from __future__ import annotations

import csv

import pytest

from ilfo.algos import ALGOS
from ilfo.cli import main
from ilfo.experiments.paper import paper_cells
from ilfo.experiments.reproduce import ABLATIONS, BUDGETS, EXPERIMENTS, TABLE1_ALGOS, plan


@pytest.mark.parametrize("name", list(EXPERIMENTS))
@pytest.mark.parametrize("budget", BUDGETS)
def test_every_experiment_plans(name, budget):
    the_plan = plan(name, budget)
    assert (the_plan.runs > 0 or the_plan.calibration is not None) and the_plan.core_hours() > 0
    for spec in the_plan.sweeps.values():
        assert all(algo in ALGOS for algo in spec.algo)
    text = the_plan.describe()
    assert "estimated" in text and name in text


def test_plans_leave_out_what_is_not_built_and_follow_the_paper():
    table1 = plan("table1", "full")
    (spec,) = table1.sweeps.values()
    assert set(spec.algo) == {a for a in TABLE1_ALGOS if a in ALGOS}
    assert spec.num_demos == (1, 4, 10) and len(spec.seed) == 5
    assert spec.config["steps"] == 1_000_000
    missing = [a for a in TABLE1_ALGOS if a not in ALGOS]
    assert all(any(a in line for line in table1.left_out) for a in missing)
    paper_variants = {c.variant for c in paper_cells() if c.table == "table4"}
    assert set(ABLATIONS) == paper_variants
    table4 = plan("table4", "full")
    assert set(table4.sweeps["variants"].variants) == {k for k, v in ABLATIONS.items() if v}
    with pytest.raises(ValueError, match="unknown experiment"):
        plan("table9", "small")
    with pytest.raises(ValueError, match="budget"):
        plan("table1", "huge")


def test_table1_smoke_runs_into_a_report(tmp_path, capsys):
    root = tmp_path / "t1"
    assert main(["reproduce", "table1", "--budget", "smoke", "--dir", str(root),
                 "--no-progress"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "estimated" in out and "report:" in out
    rows = list(csv.DictReader((root / "report" / "cells.csv").open()))
    (spec,) = plan("table1", "smoke").sweeps.values()
    assert sorted(r["algo"] for r in rows) == sorted(spec.algo)
    assert all(r["finished"] == "True" and r["versus_paper"] == "other demos" for r in rows)
    text = (root / "report" / "report.md").read_text()
    assert all(f"{a}: not built yet" in text for a in TABLE1_ALGOS if a not in ALGOS)
    # Table 3's distances of one of these runs: 10 rollouts against 10 expert trajectories.
    from ilfo.experiments.distances import SPACES, run_distances

    run_dir = next((root / "table1" / "runs").glob("Hopper-v5__oops-td3__*"))
    values = run_distances(run_dir, episodes=2, experts=2)
    assert set(values) == set(SPACES) and all(v > 0 for v in values.values())
    # Run again: everything is done, nothing trains, the report is rewritten.
    assert main(["reproduce", "table1", "--budget", "smoke", "--dir", str(root),
                 "--no-progress"]) == 0  # fmt: skip


def test_calibration_smoke_and_its_numbers(tmp_path):
    """The calibration's smoke budget: the expert, its noisy versions, zero and random actions;
    the expert's proxy return is the highest and the rank correlation is written."""
    from ilfo.experiments.calibration import calibrate, spearman

    points = calibrate("Hopper-v5", (0.0, 1.0), episodes=1, horizon=100)
    assert [p.policy for p in points] == [
        "expert + N(0, 0.0^2)", "expert + N(0, 1.0^2)", "zero", "random"
    ]  # fmt: skip
    by = {p.policy: p for p in points}
    assert by["expert + N(0, 0.0^2)"].proxy_return > by["random"].proxy_return
    assert -1 <= spearman(points) <= 1
    assert main(["reproduce", "calibration", "--budget", "smoke", "--dir", str(tmp_path),
                 "--no-progress"]) == 0  # fmt: skip
    text = (tmp_path / "report" / "calibration.md").read_text()
    assert "Hopper-v5: Spearman" in text and (tmp_path / "report" / "calibration.csv").is_file()
