"""`ilfo reproduce`: every experiment plans at every budget, its variants are the paper's, and
table1's smoke budget runs end to end into a report."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

from ilfo.algos import ALGOS
from ilfo.cli import main
from ilfo.experiments.report import TABLE4_ALGOS
from ilfo.experiments.reproduce import ABLATIONS, BUDGETS, EXPERIMENTS, TABLE1_ALGOS, plan
from ilfo.experiments.sweep import expand
from ilfo.paper import paper_cells


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
    assert set(ABLATIONS) | set(TABLE4_ALGOS.values()) == paper_variants
    table4 = plan("table4", "full")
    assert set(table4.sweeps["variants"].variants) == {k for k, v in ABLATIONS.items() if v}
    # OOPS_adv and SIL are algos; SIL's on-policy TRPO in a sweep of its own.
    assert table4.sweeps["algos"].algo == ("oops-adv-td3",)
    assert table4.sweeps["on_policy"].algo == ("sil",)
    assert set(TABLE4_ALGOS) == {"oops-adv-td3", "sil"}
    with pytest.raises(ValueError, match="unknown experiment"):
        plan("table9", "small")
    with pytest.raises(ValueError, match="budget"):
        plan("table1", "huge")


def test_small_budget_of_oops_alone_takes_four_updates_per_step():
    # At one, OOPS+TD3 on Hopper is on its plateau at 300k for most seeds (the module's note).
    table4 = plan("table4", "small")
    for sub in ("default", "variants", "algos"):
        assert table4.sweeps[sub].config["updates_per_step"] == 4, sub
    assert "updates_per_step" not in table4.sweeps["on_policy"].config  # sil: does not apply
    assert plan("solvers", "small").sweeps["solvers"].config["updates_per_step"] == 4
    # Algorithm comparisons keep the paper's one update per step.
    for name in ("table1", "table2", "table3"):
        assert all("updates_per_step" not in s.config for s in plan(name, "small").sweeps.values())


def test_the_estimate_counts_updates_per_step():
    from ilfo.experiments.estimates import RUN_FIXED_CORE_SECONDS, UPDATE_SHARE
    from ilfo.experiments.reproduce import Plan
    from ilfo.experiments.sweep import SweepSpec

    def hours(algo, **config):
        spec = SweepSpec(algo=(algo,), config={"steps": 100_000, "preset": "fast", **config})
        return Plan("x", "small", {"x": spec}, ()).core_hours()

    share, fixed = UPDATE_SHARE["fast"], RUN_FIXED_CORE_SECONDS / 3600
    assert hours("oops-td3", updates_per_step=4) - fixed == pytest.approx(
        (hours("oops-td3") - fixed) * (1 - share + 4 * share)
    )
    assert hours("oops-td3", updates_per_step=4) > 2.5 * hours("oops-td3")


def test_the_estimate_counts_each_runs_fixed_cost():
    """A run costs its start (compilation, envs, evaluations) whatever its steps: N runs' estimate
    is N fixed costs above what their steps cost, which tiny runs' estimate is mostly; a run
    trained to its end costs nothing more, one checkpointed on its way its start again."""
    from ilfo.experiments.estimates import RUN_FIXED_CORE_SECONDS
    from ilfo.experiments.reproduce import Plan
    from ilfo.experiments.sweep import SweepSpec

    def seconds(runs, steps, root=None):
        spec = SweepSpec(algo=("oops-td3",), seed=tuple(range(runs)), config={"steps": steps})
        return 3600 * Plan("x", "small", {"x": spec}, ()).core_hours(root)

    for runs in (1, 4):
        per_steps = seconds(runs, 2000) - seconds(runs, 1000)  # what 1,000 more steps add
        assert per_steps > 0
        fixed = seconds(runs, 1000) - per_steps  # the estimate at no steps
        assert fixed >= runs * RUN_FIXED_CORE_SECONDS * (1 - 1e-9)
    smoke = plan("table1", "smoke")
    assert 3600 * smoke.core_hours() >= smoke.runs * RUN_FIXED_CORE_SECONDS
    assert 3600 * smoke.core_hours() < 2 * smoke.runs * RUN_FIXED_CORE_SECONDS  # mostly fixed


def test_the_estimate_counts_the_measures_of_final_rollouts():
    """The solver figure's 100 pairs a run take about as long as a 300k-step run trains."""
    from ilfo.experiments.estimates import MEASURE_SECONDS_PER_PAIR

    solvers, table3 = plan("solvers", "small"), plan("table3", "small")
    assert solvers.measure_hours() == pytest.approx(
        100 * MEASURE_SECONDS_PER_PAIR["solvers"] / 3600
    )
    assert table3.measure_hours() == pytest.approx(
        table3.runs * 100 * MEASURE_SECONDS_PER_PAIR["distances"] / 3600
    )
    trained_only = dataclasses.replace(solvers, measures=())
    assert solvers.core_hours() == pytest.approx(
        trained_only.core_hours() + solvers.measure_hours()
    )
    assert "of them measuring the final rollouts" in solvers.describe()
    # Smoke runs' 100-step episodes: pairs a hundredth as long.
    smoke = plan("solvers", "smoke")
    assert smoke.measure_hours() == pytest.approx(
        4 * MEASURE_SECONDS_PER_PAIR["solvers"] / 100 / 3600
    )


def test_the_estimate_left_counts_checkpoints_and_kept_pairs(tmp_path):
    """What a directory already holds comes off the estimate: a run's steps up to its newest
    complete checkpoint, and the pairs of a measure kept (all of them once it is written)."""
    from ilfo.experiments.estimates import MEASURE_SECONDS_PER_PAIR, RUN_FIXED_CORE_SECONDS
    from ilfo.training.run_dir import CHECKPOINT_FILES, REPLAY_OMITTED, SOLVERS_FILE

    solvers = plan("solvers", "small")
    ((sub, spec),) = solvers.sweeps.items()
    (run,) = expand(spec)
    run_dir = tmp_path / sub / "runs" / run.name
    assert solvers.core_hours(tmp_path) == pytest.approx(solvers.core_hours())  # nothing yet
    assert f"{tmp_path}" not in solvers.describe(tmp_path)

    def checkpoint(step, complete=True):
        path = run_dir / "checkpoints" / f"step_{step:08d}"
        path.mkdir(parents=True)
        for name in (*CHECKPOINT_FILES, REPLAY_OMITTED)[: None if complete else 1]:
            (path / name).write_text("{}")

    checkpoint(100_000)
    checkpoint(200_000, complete=False)  # a damaged one does not count
    trained = dataclasses.replace(solvers, measures=())
    fixed = RUN_FIXED_CORE_SECONDS / 3600  # a resume starts the run again
    assert trained.core_hours(tmp_path) == pytest.approx(
        fixed + (trained.core_hours() - fixed) * 2 / 3
    )
    partial = run_dir / ".solvers.partial.json"
    partial.write_text(json.dumps({"key": {}, "pairs": {str(i): {} for i in range(40)}}))
    per_pair = MEASURE_SECONDS_PER_PAIR["solvers"] / 3600
    assert solvers.measure_hours(tmp_path) == pytest.approx(60 * per_pair)
    assert "left: " in solvers.describe(tmp_path)
    partial.write_text("{damaged")
    assert solvers.measure_hours(tmp_path) == pytest.approx(100 * per_pair)
    (run_dir / SOLVERS_FILE).write_text("")  # damaged: measured again
    assert solvers.measure_hours(tmp_path) == pytest.approx(100 * per_pair)
    (run_dir / SOLVERS_FILE).write_text(json.dumps({"key": {}, "values": {}}))
    assert solvers.measure_hours(tmp_path) == 0
    checkpoint(run.steps)  # trained to its end: no start left to pay for
    assert solvers.core_hours(tmp_path) == 0


@pytest.mark.integration
def test_table1_smoke_runs_into_a_report(tmp_path, capsys, monkeypatch):
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

    def worker_starts():
        files = (root / "table1" / "attempts").glob("*.jsonl")
        return sum(line.count('"event": "start"') for f in files for line in f.open())

    # Run again: everything is done, no worker starts, the report is rewritten.
    started = worker_starts()
    (root / "report" / "report.md").unlink()
    assert main(["reproduce", "table1", "--budget", "smoke", "--dir", str(root),
                 "--no-progress"]) == 0  # fmt: skip
    assert worker_starts() == started > 0 and (root / "report" / "report.md").is_file()
    # Table 3 and the solver figure measure these runs' final rollouts: reproduce's wiring with
    # the sweeps stubbed out (the runs above stand in for the experiments' own).
    from ilfo.experiments import reproduce as reproduce_module
    from ilfo.experiments.report import collect_runs

    runs, _ = collect_runs([root / "table1"])
    oops = [r for r in runs if r.algo == "oops-td3"]
    monkeypatch.setattr("ilfo.experiments.backends.run_sweeps", lambda *a, **k: [])
    monkeypatch.setattr("ilfo.experiments.report.collect_runs", lambda paths: (oops, []))
    for name, table in (("table3", "distances.md"), ("solvers", "solvers.md")):
        _, written = reproduce_module.reproduce(name, "smoke", tmp_path / name, lambda: None)
        text = (tmp_path / name / "report" / table).read_text()
        assert "Hopper-v5" in text and any(p.name == table for p in written)
    distances = (tmp_path / "table3" / "report" / "distances.md").read_text()
    paper = next(c for c in paper_cells() if c.table == "table3" and c.algo == "oops-td3"
                 and c.env == "Hopper-v5" and c.space == "s")  # fmt: skip
    assert f"({paper.mean:.2f})" in distances  # the paper's number beside ilfo's
    cached = json.loads((oops[0].run_dir / "distances.json").read_text())  # cached in the run
    assert cached["key"]["trained_step"] == oops[0].trained_step == oops[0].steps
    # A run's snapshot (sweeps carried between machines) keeps its measures.
    from ilfo.training.checkpoint import snapshot_run

    carried = snapshot_run(oops[0].run_dir, tmp_path / "carried")
    for name in ("distances.json", "solvers.json"):
        assert (carried / name).read_bytes() == (oops[0].run_dir / name).read_bytes()


def test_measures_are_cached_per_trained_step_and_skip_unfinished_runs(tmp_path):
    """A run trained on since its distances were measured is measured again; an unfinished
    run's newest checkpoint is not its final policy, so it is left out, and said so."""
    from types import SimpleNamespace

    from ilfo.experiments.measures import cached_measure, write_distances

    calls = []

    def compute():
        calls.append(1)
        return {"s": float(len(calls))}

    run = SimpleNamespace(run_dir=tmp_path, trained_step=1000)
    lines = []
    assert cached_measure(run, "d.json", 10, compute, lines.append) == {"s": 1.0}
    # Minutes of rollouts and solves are announced, and timed; a kept value is not.
    assert len(lines) == 2 and "measuring d, 10 final rollouts" in lines[0]
    assert lines[1].startswith(f"{tmp_path.name}: d measured in ")
    assert cached_measure(run, "d.json", 10, compute, lines.append) == {"s": 1.0}
    assert len(calls) == 1
    assert len(lines) == 2
    assert cached_measure(run, "d.json", 5, compute) == {"s": 2.0}  # other episodes
    run.trained_step = 2000
    assert cached_measure(run, "d.json", 5, compute) == {"s": 3.0}  # trained on since
    for damaged in ("", "[1, 2]", '{"key": {"trained_step": 2000, "episodes": 5}}'):
        (tmp_path / "d.json").write_text(damaged)  # a power loss, a hand edit: measured again
        assert cached_measure(run, "d.json", 5, compute) == {"s": float(len(calls))}
    assert len(calls) == 6
    unfinished = SimpleNamespace(run_dir=tmp_path / "Hopper-v5__oops-td3__0", finished=False)
    (out := tmp_path / "out").mkdir()
    write_distances([unfinished], out)
    assert "Not measured, unfinished: Hopper-v5__oops-td3__0." in (out / "distances.md").read_text()


def _trajectories(count, seed):
    from ilfo.experiments.distances import Trajectory

    rng = np.random.default_rng(seed)
    return [Trajectory(rng.normal(size=(6, 2)), rng.normal(size=(5, 1))) for _ in range(count)]


def _measure_stopped_at(pair, tmp_path, monkeypatch, rollouts, experts):
    """A run whose final rollouts are ``rollouts``, its pairs' measurement stopped by Ctrl-C at
    the ``pair``-th pair: the run, the measure (its calls counted in ``calls``), and ``shown``,
    the rollouts the run is said to have (to swap them)."""
    from types import SimpleNamespace

    from ilfo.experiments import distances
    from ilfo.experiments.measures import measure_pairs

    shown = {"rollouts": rollouts}
    monkeypatch.setattr(distances, "final_rollouts", lambda *a, **k: (shown["rollouts"], experts))
    calls = []

    def measure(rollout, expert):
        calls.append((id(rollout), id(expert)))
        if len(calls) == pair:
            raise KeyboardInterrupt
        return {"d": distances.wasserstein(rollout.observations, expert.observations)}

    run = SimpleNamespace(run_dir=tmp_path, trained_step=1000)
    with pytest.raises(KeyboardInterrupt):
        measure_pairs(run, "m.json", 2, measure)
    return run, measure, calls, shown


def test_an_interrupted_measurement_continues_from_its_last_pair(tmp_path, monkeypatch):
    """The solver figure's pairs take about a minute each: a measurement stopped part-way
    keeps its pairs and, run again, measures only the others, to the uninterrupted mean."""
    from ilfo.experiments.measures import measure_pairs

    trajectories = _trajectories(5, seed=0)
    rollouts, experts = trajectories[:3], trajectories[3:]
    run, measure, calls, _ = _measure_stopped_at(4, tmp_path, monkeypatch, rollouts, experts)
    assert len(json.loads((tmp_path / ".m.partial.json").read_text())["pairs"]) == 3
    # A snapshot would carry it: the solver figure's partial file is among the kept files.
    from ilfo.training.run_dir import SNAPSHOT_FILES, partial_measure_file

    assert partial_measure_file("m.json") == ".m.partial.json"
    assert ".solvers.partial.json" in SNAPSHOT_FILES
    lines = []
    values = measure_pairs(run, "m.json", 2, measure, lines.append)
    assert len(calls) == 4 + 3  # the fourth pair again, then the last two; not the first three
    expected = np.mean([measure(r, e)["d"] for r in rollouts for e in experts])
    assert values == {"d": pytest.approx(expected, rel=1e-12)}
    assert "3 of 6 pairs kept from before" in lines[1]
    assert not (tmp_path / ".m.partial.json").exists() and (tmp_path / "m.json").is_file()
    # Pairs kept for another final policy are measured again.
    (tmp_path / ".m.partial.json").write_text(
        json.dumps({"key": {"trained_step": 500, "episodes": 2}, "pairs": {"0,0": {"d": 9.0}}})
    )
    run.trained_step, before = 2000, len(calls)
    assert measure_pairs(run, "m.json", 2, measure)["d"] == pytest.approx(expected, rel=1e-12)
    assert len(calls) - before == 6
    # So are pairs in a damaged file.
    (tmp_path / ".m.partial.json").write_text('{"key": {"trained_st')
    run.trained_step, before = 3000, len(calls)
    assert measure_pairs(run, "m.json", 2, measure)["d"] == pytest.approx(expected, rel=1e-12)
    assert len(calls) - before == 6
    # Stopped after its last pair, before the finished measure is written: no pair is lost.
    from ilfo import files

    write = files.write_json_atomic

    def stop_at_the_finished_measure(path, value):
        if path.name == "m.json":
            raise KeyboardInterrupt
        write(path, value)

    monkeypatch.setattr(files, "write_json_atomic", stop_at_the_finished_measure)
    run.trained_step, before = 4000, len(calls)
    with pytest.raises(KeyboardInterrupt):
        measure_pairs(run, "m.json", 2, measure)
    monkeypatch.setattr(files, "write_json_atomic", write)
    assert measure_pairs(run, "m.json", 2, measure)["d"] == pytest.approx(expected, rel=1e-12)
    assert len(calls) - before == 6 and not (tmp_path / ".m.partial.json").exists()


def test_pairs_of_other_rollouts_of_the_same_policy_are_measured_again(tmp_path, monkeypatch):
    """Continued on another machine, the same final policy can roll out a little differently
    (the last bits of its floats): the kept pairs are of other trajectories, so a mean mixing
    them would mix two measurements."""
    from ilfo.experiments import distances
    from ilfo.experiments.measures import measure_pairs

    trajectories = _trajectories(4, seed=1)
    rollouts, experts = trajectories[:2], trajectories[2:]
    run, measure, calls, shown = _measure_stopped_at(3, tmp_path, monkeypatch, rollouts, experts)
    nudged = rollouts[0].observations.copy()
    nudged[0, 0] = np.nextafter(nudged[0, 0], np.inf)  # one float, one ulp
    shown["rollouts"] = [distances.Trajectory(nudged, rollouts[0].actions), rollouts[1]]
    assert distances.trajectories_digest(shown["rollouts"]) != distances.trajectories_digest(
        rollouts
    )
    lines, before = [], len(calls)
    measure_pairs(run, "m.json", 2, measure, lines.append)
    assert len(calls) - before == 4  # every pair again, not the two kept
    assert "2 pairs kept from before are of another final policy or other rollouts" in lines[1]


@pytest.mark.integration
def test_calibration_smoke_and_its_numbers(tmp_path):
    """The calibration's smoke budget: the expert, its noisy versions, zero and random actions;
    the expert's proxy return is the highest, the noisier the lower (measured: -172, -196,
    -243 for zero actions, -259 for random ones), and the rank correlation is written."""
    from ilfo.experiments.calibration import calibrate, spearman

    points = calibrate("Hopper-v5", (0.0, 1.0), episodes=1, horizon=100)
    assert [p.policy for p in points] == [
        "expert + N(0, 0.0^2)", "expert + N(0, 1.0^2)", "zero", "random"
    ]  # fmt: skip
    by = {p.policy: p for p in points}
    proxies = [p.proxy_return for p in points]
    assert proxies == sorted(proxies, reverse=True)  # expert, noisy, zero, random
    assert by["expert + N(0, 0.0^2)"].task_score > by["random"].task_score
    assert spearman(points) > 0
    assert main(["reproduce", "calibration", "--budget", "smoke", "--dir", str(tmp_path),
                 "--no-progress"]) == 0  # fmt: skip
    text = (tmp_path / "report" / "calibration.md").read_text()
    assert "Hopper-v5: Spearman" in text and "Pearson" in text
    assert (tmp_path / "report" / "calibration.csv").is_file()


def test_calibration_correlations_against_hand_computed():
    """Spearman ranks, Pearson weighs distances: one outlier in proxy return leaves the ranks
    perfectly ordered but pulls r below 1 (r of (1, 2, 3, 4) and (1, 2, 3, 10): 0.8854)."""
    from ilfo.experiments.calibration import CalibrationPoint, pearson, spearman

    points = [
        CalibrationPoint("p", 0.0, k, float(score), float(proxy), 0.0)
        for k, (score, proxy) in enumerate([(1, 1), (2, 2), (3, 3), (4, 10)])
    ]
    assert spearman(points) == pytest.approx(1.0)
    assert pearson(points) == pytest.approx(0.8854, abs=1e-4)
    reversed_points = [dataclasses.replace(p, proxy_return=-p.proxy_return) for p in points]
    assert pearson(reversed_points) == pytest.approx(-0.8854, abs=1e-4)


def test_calibration_correlations_are_nan_without_warning_when_undefined():
    """A smoke horizon can leave every task score equal: the correlation is undefined, so it is
    NaN, quietly: any warning fails this test."""
    import warnings

    from ilfo.experiments.calibration import CalibrationPoint, pearson, spearman

    constant_score = [CalibrationPoint("p", 0.0, k, 1.0, float(k), 0.0) for k in range(4)]
    one_episode = constant_score[:1]
    varied = [CalibrationPoint("p", 0.0, k, float(k), float(k * k), 0.0) for k in range(4)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for points in (constant_score, one_episode, []):
            assert np.isnan(spearman(points))
            assert np.isnan(pearson(points))
        assert spearman(varied) == pytest.approx(1.0)


def test_reproduce_exits_1_and_names_the_runs_given_up(tmp_path, capsys, monkeypatch):
    """The report leaves out runs that failed past their retries: the command says so and
    fails (it exited 0)."""
    from ilfo.experiments import create_sweep, record_attempt

    def reproduce(name, budget, root, factory, on_change=None, log=print):
        the_plan = plan(name, budget)
        for sub, spec in the_plan.sweeps.items():
            sweep = create_sweep(root / sub, spec)
        for _ in range(spec.retries + 1):
            record_attempt(sweep, sweep.runs[0].name, "end", status="error", error="boom")
        return the_plan, [root / "report" / "report.md"]

    monkeypatch.setattr("ilfo.experiments.reproduce.reproduce", reproduce)
    args = ["reproduce", "table1", "--budget", "smoke", "--dir", str(tmp_path), "--no-progress"]
    assert main(args) == 1
    out = capsys.readouterr().out
    assert "failed: " in out and ": boom (log: " in out and "--retry-failed" in out
