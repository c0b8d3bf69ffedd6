"""Reports: the statistics against SciPy and hand computations, and a report over a fixture of
metrics files against hand-computed aggregates and the paper's numbers."""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import numpy as np
import pytest
from scipy import stats as scipy_stats

from ilfo.algos import ALGOS
from ilfo.experiments import stats
from ilfo.experiments.report import (
    build_report,
    collect_runs,
    imitates_shipped_demos,
    read_run,
)
from ilfo.experiments.report_tables import write_report
from ilfo.paper import paper_ablation, paper_cells, paper_score


def test_iqm_against_hand_and_scipy():
    assert stats.iqm(np.arange(1, 9)) == pytest.approx(4.5)  # mean of 3, 4, 5, 6
    x = np.random.default_rng(1).normal(size=(7, 3))
    assert stats.iqm(x) == pytest.approx(scipy_stats.trim_mean(x.ravel(), 0.25))
    with_nan = np.vstack([x, np.full((1, 3), np.nan)])
    assert stats.iqm(with_nan) == pytest.approx(stats.iqm(x))


def test_bootstrap_interval_matches_scipy_on_one_task():
    x = np.random.default_rng(2).normal(1.0, 0.5, size=30)
    ours = stats.stratified_bootstrap(x, stats.iqm, resamples=20000, seed=0)
    ref = scipy_stats.bootstrap(
        (x,),
        lambda s, axis: scipy_stats.trim_mean(s, 0.25, axis=axis),
        n_resamples=20000,
        method="percentile",
        random_state=np.random.default_rng(5),
    ).confidence_interval
    assert ours.value == pytest.approx(scipy_stats.trim_mean(x, 0.25))
    assert ours.low == pytest.approx(ref.low, abs=0.02)
    assert ours.high == pytest.approx(ref.high, abs=0.02)
    assert ours.low < ours.value < ours.high
    custom = stats.stratified_bootstrap(x, lambda s: float(np.nanmean(s)), resamples=2000)
    plain = stats.stratified_bootstrap(x, stats.mean, resamples=2000)
    assert (custom.low, custom.high) == pytest.approx((plain.low, plain.high))  # same draws


def test_bootstrap_is_stratified_by_task():
    """Task A's runs are all 0, task B's all 1 (different counts, NaN padding): resampling each
    task from its own runs keeps the pooled IQM's runs 3 to 5, and the mean of task means at
    1/2, in every sample; pooling the runs first would not."""
    scores = np.full((5, 2), np.nan)
    scores[:3, 0] = 0.0
    scores[:, 1] = 1.0
    interval = stats.stratified_bootstrap(scores, stats.mean, resamples=500)
    assert (interval.value, interval.low, interval.high) == pytest.approx((1 / 2,) * 3)
    pooled_iqm = scipy_stats.trim_mean([0.0] * 3 + [1.0] * 5, 0.25)
    interval = stats.stratified_bootstrap(scores, stats.iqm, resamples=500)
    assert (interval.value, interval.low, interval.high) == pytest.approx((pooled_iqm,) * 3)


def test_mean_and_median_are_over_task_means_as_rliable():
    """rliable's aggregate_mean and aggregate_median: the mean and the median of the per-task
    mean runs, so a task's seed count does not weigh it; IQM pools the runs."""
    one_task = np.array([0.0, 0.0, 0.0, 1.0, 1.0])
    assert stats.median(one_task) == pytest.approx(0.4)  # the runs' median would be 0
    assert stats.mean(one_task) == pytest.approx(0.4)
    scores = np.full((4, 3), np.nan)
    scores[:, 0] = [0.0, 0.0, 0.0, 0.0]
    scores[:2, 1] = [1.0, 1.0]
    scores[:3, 2] = [0.2, 0.5, 0.8]
    assert stats.mean(scores) == pytest.approx((0.0 + 1.0 + 0.5) / 3)  # runs' mean: 3.5/9
    assert stats.median(scores) == pytest.approx(0.5)
    for aggregate in (stats.mean, stats.median):  # vectorised, as called once per draw
        fast = stats.stratified_bootstrap(scores, aggregate, resamples=300, seed=4)
        wrapped = lambda s, a=aggregate: a(s)  # noqa: E731 (not in _ROWWISE: one call per draw)
        slow = stats.stratified_bootstrap(scores, wrapped, resamples=300, seed=4)
        assert (fast.low, fast.high) == pytest.approx((slow.low, slow.high))


def test_profile_and_probability_of_improvement_by_hand():
    assert stats.performance_profile([0.1, 0.5, 0.9], [0.0, 0.5, 1.0]) == pytest.approx(
        [1.0, 1 / 3, 0.0]
    )
    x, y = np.array([1.0, 2.0]), np.array([2.0, 0.0])
    assert stats.probability_of_improvement(x, y) == pytest.approx((2 + 0.5) / 4)
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(6, 2)), rng.normal(0.5, size=(4, 2))
    u = [scipy_stats.mannwhitneyu(a[:, t], b[:, t]).statistic / (6 * 4) for t in range(2)]
    assert stats.probability_of_improvement(a, b) == pytest.approx(np.mean(u))
    interval = stats.probability_of_improvement_interval(a, b, resamples=500)
    assert interval.value == pytest.approx(stats.probability_of_improvement(a, b))
    assert 0 <= interval.low < interval.value < interval.high <= 1
    profile, low, high = stats.performance_profile_band(a, np.array([0.0]), resamples=200)
    assert profile == pytest.approx(stats.performance_profile(a, [0.0]))
    assert low[0] <= profile[0] <= high[0] and low[0] < high[0]


def test_intervals_of_profiles_and_improvement_are_stratified_bootstraps():
    """Resampled within each task, X's runs beat Y's on one task and lose on the other in every
    sample (P = 1/2 exactly), and a profile over one all-0 and one all-1 task is 5/8 above 0.5
    in every sample; pooling the runs first would spread both. On one task of 20 runs, half
    above tau, the band is the binomial's 2.5% and 97.5% quantiles, 6/20 and 14/20."""
    x, y = np.full((5, 2), np.nan), np.full((4, 2), np.nan)
    x[:3, 0], x[:, 1] = 1.0, 0.0
    y[:, 0], y[:2, 1] = 0.0, 1.0
    interval = stats.probability_of_improvement_interval(x, y, resamples=300)
    assert (interval.value, interval.low, interval.high) == pytest.approx((0.5,) * 3)
    scores = np.full((5, 2), np.nan)
    scores[:3, 0], scores[:, 1] = 0.0, 1.0
    profile, low, high = stats.performance_profile_band(scores, np.array([0.5]), resamples=300)
    assert (profile[0], low[0], high[0]) == pytest.approx((5 / 8,) * 3)
    half = np.repeat([0.0, 1.0], 10)
    profile, low, high = stats.performance_profile_band(half, np.array([0.5]), resamples=4000)
    assert (profile[0], low[0], high[0]) == pytest.approx((0.5, 0.3, 0.7))
    interval = stats.probability_of_improvement_interval(half, 1 - half, resamples=4000)
    # P(X > Y) of two resampled halves: (k m + (20 - k)(20 - m)) / 400 + ties / 2, k and m ~
    # Binomial(20, 1/2) the 1s drawn; a reference by simulation, another random stream.
    rng = np.random.default_rng(123)
    k, m = rng.binomial(20, 0.5, size=(2, 200_000))
    reference = (k * (20 - m) + 0.5 * (k * m + (20 - k) * (20 - m))) / 400
    assert interval.value == pytest.approx(0.5)
    expected = np.percentile(reference, [2.5, 97.5])
    assert (interval.low, interval.high) == pytest.approx(tuple(expected), abs=0.02)


def test_a_run_is_finished_by_its_last_episode_not_its_last_evaluation(tmp_path):
    """A budget of 2,500 steps with evaluations every 1,000: the last evaluation is at 2,000,
    and the run is finished once an episode reached 2,500."""
    run = _fake_run(tmp_path, "r", env="Hopper-v5", algo="oops-td3", seed=0, scores=[0.5, 0.6],
                    steps=2500)  # fmt: skip
    assert not read_run(run).finished
    with (run / "metrics.csv").open("a") as f:
        f.write("2500,5,,\n")
    result = read_run(run)
    assert result.finished and result.final_step == 2000 and result.final_score == 0.6


def test_a_diverged_run_is_flagged_not_called_below_the_paper(tmp_path):
    """A NaN final evaluation makes its cell's mean NaN: flagged as such, and the report (its
    profile's band included: no finite run at all) still written."""
    _fake_run(tmp_path, "h0", env="Hopper-v5", algo="oops-td3", seed=0, scores=[0.5, math.nan])
    report = build_report(collect_runs([tmp_path])[0], resamples=50)
    assert report.cell("Hopper-v5", "oops-td3", 1).versus_paper == "non-finite score"
    assert "report.md" in {p.name for p in write_report(report, tmp_path / "out", sources=[])}
    profile, low, high = stats.performance_profile_band(np.full((2, 1), np.nan), [0.5])
    assert np.isnan([profile, low, high]).all()


def test_paper_data_has_the_tables():
    tables = {c.table for c in paper_cells()}
    assert tables == {"table1", "table2", "table3", "table4"}
    hopper = paper_score("Hopper-v5", "oops-td3", 1)
    assert (hopper.mean, hopper.std) == (0.98, 0.02)
    assert paper_score("Walker2d-v5", "opolo", 1).mean == 0.80
    assert paper_score("Hopper-v5", "firl-fkl", 1).mean == 0.91
    assert paper_ablation("Hopper-v5", "lambda_0.1") is not None


def _fake_run(root, name, *, env, algo, seed, scores, steps=None, demos=None, num_demos=1):
    run = root / name
    run.mkdir(parents=True)
    n = len(scores)
    config = {"env": env, "algo": algo, "seed": seed, "num_demos": num_demos,
              "steps": steps or 1000 * n, "demos": demos}  # fmt: skip
    (run / "config.json").write_text(json.dumps(config))
    with (run / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["step", "episode", "eval_score_norm", "eval_return_norm"])
        for k, score in enumerate(scores):
            writer.writerow([1000 * (k + 1) - 500, 2 * k + 1, "", ""])  # an episode row
            writer.writerow([1000 * (k + 1), 2 * k + 2, score, score / 2])
    return run


def test_a_path_to_the_shipped_demos_is_the_shipped_demos():
    """`--demos data/experts/ENV/demos.npz` imitates what the default does, so its cell is set
    beside the paper's; another env's file, or another file, is not."""
    assert imitates_shipped_demos(None, "Walker2d-v5")
    assert imitates_shipped_demos("data/experts/Walker2d-v5/demos.npz", "Walker2d-v5")
    assert imitates_shipped_demos("/home/u/ilfo/data/experts/Walker2d-v5/demos.npz", "Walker2d-v5")
    assert not imitates_shipped_demos("data/experts/Hopper-v5/demos.npz", "Walker2d-v5")
    assert not imitates_shipped_demos("mine/Walker2d-v5/demos.npz", "Walker2d-v5")
    assert not imitates_shipped_demos("data/demos/Hopper-v5-scripted.npz", "Hopper-v5")


def test_a_run_that_imitated_an_expert_replaced_since_is_not_set_beside_the_paper(tmp_path):
    """Its demos.json names the file's sha256 as the run read it; the shipped file has other
    bytes once the expert is re-exported, and the run's cell is then "other demos"."""
    import hashlib

    from ilfo.training.build import default_demos_path

    shipped = hashlib.sha256(default_demos_path("Hopper-v5").read_bytes()).hexdigest()
    for name, sha in (("now", shipped), ("before", "0" * 64)):
        run = _fake_run(tmp_path / name, "r", env="Hopper-v5", algo="oops-td3", seed=0,
                        scores=[0.5, 0.97])  # fmt: skip
        (run / "demos.json").write_text(json.dumps({"sha256": sha}))
    now = build_report(collect_runs([tmp_path / "now"])[0], resamples=100)
    assert now.cell("Hopper-v5", "oops-td3", 1).versus_paper == "within"
    before = build_report(collect_runs([tmp_path / "before"])[0], resamples=100)
    assert before.cell("Hopper-v5", "oops-td3", 1).versus_paper == "other demos"


def test_a_cell_whose_shipped_expert_is_weaker_than_the_papers_says_so(tmp_path):
    """A weak expert's demos are easier to match, so its cell's verdict carries the expert's
    strength (from its card); a cell of an expert at the paper's level, or of other demos,
    does not."""
    from ilfo.experiments.report import STRONG_EXPERT, shipped_expert_fraction

    duck = shipped_expert_fraction("MinitaurBulletDuckEnv-v0")
    assert duck is not None and duck < STRONG_EXPERT  # the shipped Duck expert: 51%
    assert shipped_expert_fraction("Hopper-v5") >= STRONG_EXPERT
    for env, demos in (("MinitaurBulletDuckEnv-v0", None), ("Hopper-v5", None),
                       ("Walker2d-v5", "mine/demos.npz")):  # fmt: skip
        _fake_run(tmp_path / "runs", env, env=env, algo="oops-td3", seed=0,
                  scores=[0.5, 0.97], demos=demos)  # fmt: skip
    report = build_report(collect_runs([tmp_path / "runs"])[0], resamples=100)
    assert report.cell("MinitaurBulletDuckEnv-v0", "oops-td3", 1).expert_fraction == duck
    assert report.cell("Walker2d-v5", "oops-td3", 1).expert_fraction is None
    write_report(report, tmp_path / "report")
    table = (tmp_path / "report" / "report.md").read_text()
    rows = {line.split(" | ")[0].strip("| "): line for line in table.splitlines()}
    assert f"within (expert at {duck:.0%} of the paper's)" in rows["MinitaurBulletDuckEnv-v0"]
    assert "expert at" not in rows["Hopper-v5"] and "| within (1 seed" in rows["Hopper-v5"]
    assert "| other demos |" in rows["Walker2d-v5"]
    with (tmp_path / "report" / "cells.csv").open() as f:
        fractions = {r["env"]: r["expert_fraction_of_paper"] for r in csv.DictReader(f)}
    assert float(fractions["MinitaurBulletDuckEnv-v0"]) == duck
    assert fractions["Walker2d-v5"] == ""


def test_runs_that_observed_other_than_the_default_contact_forces_are_a_cell_of_their_own(
    tmp_path,
):
    def run_with(name, algo, seed, **contact_forces):
        run = _fake_run(tmp_path, name, env="Humanoid-v5", algo=algo, seed=seed, scores=[0.5])
        config = json.loads((run / "config.json").read_text())
        (run / "config.json").write_text(json.dumps({**config, **contact_forces}))

    run_with("dropped", "oops-td3", 0, contact_forces=False)  # imitation's default
    run_with("default", "oops-td3", 1, contact_forces=None)
    run_with("old", "oops-td3", 2)  # written before the setting: they were observed
    run_with("observed", "oops-td3", 3, contact_forces=True)
    run_with("control", "td3", 0)  # the task reward observes them by default
    run_with("control-dropped", "td3", 1, contact_forces=False)
    runs, _ = collect_runs([tmp_path])
    variants = {(r.algo, r.seed): r.variant for r in runs}
    assert read_run(tmp_path / "old", "w_greedy").variant == "w_greedy+contact-forces"
    assert variants == {
        ("oops-td3", 0): None,
        ("oops-td3", 1): None,
        ("oops-td3", 2): "contact-forces",
        ("oops-td3", 3): "contact-forces",
        ("td3", 0): None,
        ("td3", 1): "no-contact-forces",
    }


def test_runs_whose_reward_settings_differ_from_the_algos_are_a_cell_of_their_own(tmp_path):
    """A run given other reward settings (``--pwil-subsample 20``) is not a seed of the default
    cell; the seed (set by the trainer), a setting written out at its default, and a config
    that predates a setting are."""

    def run_with(name, seed, **settings):
        run = _fake_run(tmp_path, name, env="Walker2d-v5", algo="pwil-td3", seed=seed,
                        scores=[0.5])  # fmt: skip
        config = json.loads((run / "config.json").read_text())
        (run / "config.json").write_text(json.dumps({**config, **settings}))

    run_with("default", 0)
    run_with("old", 1, pwil={"alpha": 5.0, "beta": 5.0, "horizon": None})
    run_with("written", 2, pwil={"alpha": 5.0, "subsample": 1, "kernel_dim": None, "seed": 2})
    run_with("own", 3, pwil={"subsample": 20, "kernel_dim": 23, "seed": 3})
    run_with("alpha", 4, pwil={"alpha": 2.5})
    runs, _ = collect_runs([tmp_path])
    assert {r.seed: r.variant for r in runs} == {
        0: None,
        1: None,
        2: None,
        3: "pwil.subsample=20+pwil.kernel_dim=23",
        4: "pwil.alpha=2.5",
    }
    assert read_run(tmp_path / "own", "w_greedy").variant == "w_greedy"  # a sweep's says how
    report = build_report(runs, resamples=100)
    assert report.cell("Walker2d-v5", "pwil-td3", 1).versus_paper == "within"  # 0.71 +- 2 * 0.3
    assert len(report.cell("Walker2d-v5", "pwil-td3", 1).runs) == 3


def _written_config(**settings):
    """A config as a run writes it (every part resolved as the trainer builds it)."""
    from ilfo.training import TrainConfig

    return dataclasses.asdict(TrainConfig(env="Hopper-v5", **settings).resolved(1000))


@pytest.mark.parametrize("algo", sorted(ALGOS))
def test_a_run_at_the_defaults_has_no_settings_to_name(algo, tmp_path):
    # What the trainer itself sets (DDPG's TD3 fields, the time augmentation of fixed-horizon
    # runs, max_time) is not a change; nor is a preset that does not change the agent.
    run = _fake_run(tmp_path, "r", env="Hopper-v5", algo=algo, seed=0, scores=[0.5])
    (run / "config.json").write_text(json.dumps(_written_config(algo=algo)))
    assert read_run(run).settings == ()
    (run / "config.json").write_text(json.dumps(_written_config(algo=algo, preset="fast")))
    uses_preset = algo in ("oops-td3", "oops-ddpg", "pwil-td3", "oops-adv-td3", "td3")
    uses_preset |= algo in ("oops-td7", "td7")  # TD7's presets size it too
    assert read_run(run).settings == (("fast preset",) if uses_preset else ())


def test_a_cell_names_its_training_settings_and_warns_when_its_runs_differ(tmp_path):
    """Runs trained otherwise than the defaults say how (the preset where it changes the agent,
    steps, updates per step, agent fields); a cell whose runs differ warns and names the seeds,
    rather than averaging two protocols silently."""

    def run_with(name, algo, seed, **settings):
        run = _fake_run(tmp_path, name, env="Hopper-v5", algo=algo, seed=seed, scores=[0.5])
        config = _written_config(algo=algo, seed=seed, preset="fast", **settings)
        (run / "config.json").write_text(json.dumps(config))

    from ilfo.agents.td3 import TD3Config

    run_with("a", "oops-td3", 0)
    run_with("b", "oops-td3", 1, updates_per_step=4)
    td3 = dataclasses.replace(TD3Config.fast(), batch_size=128)
    run_with("c", "oops-td3", 2, td3=td3, steps=300_000, fixed_horizon=False)
    run_with("d", "opolo", 0)  # OPOLO's agent is the same at either preset
    run_with("e", "sil", 0)
    runs, _ = collect_runs([tmp_path])
    assert {(r.algo, r.seed): r.settings for r in runs} == {
        ("oops-td3", 0): ("fast preset",),
        ("oops-td3", 1): ("fast preset", "4 updates/step"),
        ("oops-td3", 2): ("fast preset", "300k steps", "standard episodes", "td3.batch_size=128"),
        ("opolo", 0): (),
        ("sil", 0): (),
    }
    with pytest.warns(UserWarning, match=r"Hopper-v5 oops-td3 demos 1: .*different settings"):
        report = build_report(runs, resamples=100)
    cell = report.cell("Hopper-v5", "oops-td3", 1)
    assert cell.settings == ("fast preset",)
    assert cell.settings_text == (
        "fast preset; 4 updates/step (seeds 1 only); 300k steps (seeds 2 only); "
        "standard episodes (seeds 2 only); td3.batch_size=128 (seeds 2 only)"
    )
    write_report(report, tmp_path / "report")
    rows = {r["algo"]: r for r in csv.DictReader((tmp_path / "report" / "cells.csv").open())}
    assert rows["oops-td3"]["settings"] == cell.settings_text and rows["opolo"]["settings"] == ""
    text = (tmp_path / "report" / "report.md").read_text()
    assert "| fast preset; 4 updates/step (seeds 1 only);" in text
    # SIL's Table 4 row compares it with OOPS+TD3, trained otherwise: the row says so.
    (sil_row,) = [line for line in text.splitlines() if "| sil | 1 | sil |" in line]
    assert sil_row.endswith(f"| this: defaults; oops-td3: {cell.settings_text} |")


def test_report_over_a_fixture_against_hand_computations(tmp_path):
    finals = {0: 0.9, 1: 1.0, 2: 0.5}
    for seed, final in finals.items():
        _fake_run(tmp_path, f"h{seed}", env="Hopper-v5", algo="oops-td3", seed=seed,
                  scores=[0.1, 0.5, final])  # fmt: skip
    for seed, final in {0: 0.2, 1: 0.4}.items():
        _fake_run(tmp_path, f"p{seed}", env="Hopper-v5", algo="pwil-td3", seed=seed,
                  scores=[0.1, final])  # fmt: skip
    _fake_run(tmp_path, "w0", env="Walker2d-v5", algo="oops-td3", seed=0, scores=[0.95],
              steps=2000)  # unfinished: half its steps  # fmt: skip
    _fake_run(tmp_path, "own", env="Hopper-v5", algo="oops-td3", seed=0, scores=[0.5],
              demos="mine.npz", num_demos=4)  # fmt: skip
    (tmp_path / "noeval").mkdir()
    (tmp_path / "noeval" / "config.json").write_text(json.dumps({"env": "Hopper-v5"}))
    (tmp_path / "noeval" / "metrics.csv").write_text("step,eval_score_norm\n500,\n")
    runs, skipped = collect_runs([tmp_path])
    assert len(runs) == 7 and len(skipped) == 1 and "no evaluation" in skipped[0]
    report = build_report(runs, skipped=skipped, resamples=500)
    hopper = report.cell("Hopper-v5", "oops-td3", 1)
    values = np.array(list(finals.values()))
    assert hopper.mean == pytest.approx(values.mean())
    assert hopper.std == pytest.approx(values.std())
    assert hopper.iqm.value == pytest.approx(scipy_stats.trim_mean(values, 0.25))
    assert hopper.paper.mean == 0.98
    assert hopper.versus_paper == "below"  # 0.8 < 0.98 - 2 * 0.02
    pwil = report.cell("Hopper-v5", "pwil-td3", 1)
    assert pwil.mean == pytest.approx(0.3)
    walker = report.cell("Walker2d-v5", "oops-td3", 1)
    assert not walker.finished and walker.versus_paper == "within"  # 0.95 +- 2 * 0.03
    assert report.cell("Hopper-v5", "oops-td3", 4).versus_paper == "other demos"
    out = write_report(report, tmp_path / "report", sources=[str(tmp_path)])
    assert {p.name for p in out} >= {"report.md", "cells.csv", "curves_Hopper-v5.png"}
    rows = list(csv.DictReader((tmp_path / "report" / "cells.csv").open()))
    row = next(r for r in rows if r["algo"] == "oops-td3" and r["env"] == "Hopper-v5"
               and r["num_demos"] == "1")  # fmt: skip
    assert float(row["mean"]) == pytest.approx(0.8) and row["versus_paper"] == "below"
    assert float(row["return_norm_mean"]) == pytest.approx(0.4)
    aggregates = list(csv.DictReader((tmp_path / "report" / "aggregates.csv").open()))
    both = next(r for r in aggregates if r["algo"] == "oops-td3" and r["num_demos"] == "1")
    pooled = np.array([0.9, 1.0, 0.5, 0.95])  # Hopper's three seeds and Walker2d's one
    assert int(both["tasks"]) == 2 and int(both["runs"]) == 4
    assert float(both["mean"]) == pytest.approx((pooled[:3].mean() + 0.95) / 2)  # of task means
    assert float(both["median"]) == pytest.approx((pooled[:3].mean() + 0.95) / 2)
    assert float(both["iqm"]) == pytest.approx(scipy_stats.trim_mean(pooled, 0.25))
    improvement = list(csv.DictReader((tmp_path / "report" / "improvement.csv").open()))
    first = next(r for r in improvement if (r["x"], r["y"]) == ("oops-td3", "pwil-td3"))
    assert int(first["tasks"]) == 1 and float(first["p"]) == pytest.approx(1.0)
    text = (tmp_path / "report" / "report.md").read_text()
    assert "0.98 ± 0.02" in text and "1 unfinished" in text and "no evaluation" in text


def test_report_reads_sweep_variants_and_percent_differences(tmp_path):
    from ilfo.experiments import SweepSpec, create_sweep

    spec = SweepSpec(config={"steps": 2000}, variants={"lambda_0.1": {"oops": {"reg": 0.1}}})
    base_spec = SweepSpec(config={"steps": 2000})
    sweep = create_sweep(tmp_path / "ablation", spec)
    base = create_sweep(tmp_path / "base", base_spec)
    (run,) = sweep.runs
    _fake_run(sweep.root / "runs", run.name, env="Hopper-v5", algo="oops-td3", seed=0,
              scores=[0.4, 0.6])  # fmt: skip
    _fake_run(base.root / "runs", base.runs[0].name, env="Hopper-v5", algo="oops-td3", seed=0,
              scores=[0.4, 0.8])  # fmt: skip
    runs, _ = collect_runs([tmp_path])
    assert sorted((r.variant or "") for r in runs) == ["", "lambda_0.1"]
    for inside in (sweep.root / "runs", sweep.root / "runs" / run.name):  # given a sweep's part
        (alone,) = collect_runs([inside])[0]
        assert alone.variant == "lambda_0.1"
    report = build_report(runs, resamples=200)
    variant = report.cell("Hopper-v5", "oops-td3", 1, "lambda_0.1")
    assert report.percent_difference(variant) == pytest.approx(100 * (0.6 - 0.8) / 0.8)
    assert variant.paper == paper_ablation("Hopper-v5", "lambda_0.1")
    with pytest.raises(FileNotFoundError):
        collect_runs([tmp_path / "missing"])


def test_table4_algos_are_compared_with_oops_td3(tmp_path):
    for name, algo, final, steps in (
        ("o", "oops-td3", 0.8, None),
        ("a", "oops-adv-td3", 0.6, 3000),  # unfinished: 2,000 of its 3,000 steps
        ("s", "sil", 0.2, None),
    ):
        _fake_run(tmp_path, name, env="Hopper-v5", algo=algo, seed=0, scores=[0.1, final],
                  steps=steps)  # fmt: skip
    _fake_run(tmp_path, "p", env="Hopper-v5", algo="pwil-td3", seed=0, scores=[0.5])
    report = build_report(collect_runs([tmp_path])[0], resamples=200)
    adv = report.cell("Hopper-v5", "oops-adv-td3", 1)
    assert report.percent_difference(adv) == pytest.approx(100 * (0.6 - 0.8) / 0.8)
    sil = report.cell("Hopper-v5", "sil", 1)
    assert report.percent_difference(sil) == pytest.approx(100 * (0.2 - 0.8) / 0.8)
    assert sil.paper is not None and sil.paper.mean == pytest.approx(0.17)  # Table 1's row
    assert report.percent_difference(report.cell("Hopper-v5", "pwil-td3", 1)) is None
    write_report(report, tmp_path / "report", sources=[str(tmp_path)])
    text = (tmp_path / "report" / "report.md").read_text()
    paper = paper_ablation("Hopper-v5", "oops_adv")
    seeds = "1 (1 unfinished, from step 2,000); 1"  # its own; OOPS+TD3's
    assert f"| Hopper-v5 | oops-adv-td3 | 1 | oops_adv | {seeds} | -25.0 | {paper.text} |" in text


def test_a_one_seed_cell_claims_no_spread_or_interval(tmp_path):
    _fake_run(tmp_path, "h0", env="Hopper-v5", algo="oops-td3", seed=0, scores=[0.5, 0.97])
    for seed, score in enumerate([0.9, 0.8]):
        _fake_run(tmp_path, f"w{seed}", env="Walker2d-v5", algo="oops-td3", seed=seed,
                  scores=[0.5, score])  # fmt: skip
    report = build_report(collect_runs([tmp_path])[0], resamples=50)
    write_report(report, tmp_path / "out", sources=[])
    rows = (tmp_path / "out" / "report.md").read_text().splitlines()
    (hopper,) = [r for r in rows if r.startswith("| Hopper-v5 | oops-td3 |")]
    (walker,) = [r for r in rows if r.startswith("| Walker2d-v5 | oops-td3 |")]
    ilfo_columns = hopper.split(" | ")[5:8]  # mean, IQM, return: the paper's has its own ±
    assert ilfo_columns[:2] == ["0.97", "- (1 seed)"]
    assert "±" not in " ".join(ilfo_columns) and "[0.97" not in hopper
    assert "within (1 seed: a single draw)" in hopper
    assert "0.85 ± 0.05 | 0.85 [" in walker and "1 seed" not in walker


def test_a_profile_is_drawn_over_tasks_every_algo_drawn_has_runs_on(tmp_path):
    """Each curve of a profile is over the same tasks: of the algos' task sets, the one most
    (algo, task) pairs are drawn on; algos without runs on all its tasks are left out, and the
    report says which, and on what they ran."""
    from ilfo.experiments.report_figures import profile_selection

    def runs(root, algo, envs):
        for k, env in enumerate(envs):  # the report's order of tasks: its runs' (sorted) order
            _fake_run(root, f"{algo}-{k}-{env}", env=env, algo=algo, seed=0, scores=[0.5])

    three = ("Hopper-v5", "Walker2d-v5", "HalfCheetah-v5")
    wide = tmp_path / "wide"
    runs(wide, "oops-td3", three)
    runs(wide, "pwil-td3", three)
    runs(wide, "opolo", three[:2])
    runs(wide, "sil", three[:1])
    report = build_report(collect_runs([wide])[0], resamples=50)
    chosen = profile_selection(report, 1)
    # 2 algos x 3 tasks = 3 algos x 2 tasks: the more tasks; 4 x 1 fewer pairs.
    assert chosen.tasks == three
    assert [g[0] for g in chosen.groups] == ["oops-td3", "pwil-td3"]
    assert {g[0]: envs for g, envs in chosen.left_out} == {
        "opolo": three[:2],
        "sil": three[:1],
    }
    assert chosen.tasks_left_out == ()
    write_report(report, tmp_path / "wide-report")
    text = (tmp_path / "wide-report" / "report.md").read_text()
    assert (
        "- Performance profile, 1 demo: over Hopper-v5, Walker2d-v5, HalfCheetah-v5, the algos "
        "with runs on every one of them; left out: opolo, 1 demo (run on Hopper-v5, "
        "Walker2d-v5); sil, 1 demo (run on Hopper-v5)." in text
    )
    # One algo on three tasks, three on two: the two tasks, all four algos, the third task out.
    narrow = tmp_path / "narrow"
    runs(narrow, "oops-td3", three)
    for algo in ("pwil-td3", "opolo", "sil"):
        runs(narrow, algo, three[:2])
    chosen = profile_selection(build_report(collect_runs([narrow])[0], resamples=50), 1)
    assert chosen.tasks == three[:2] and len(chosen.groups) == 4 and chosen.left_out == ()
    assert chosen.tasks_left_out == ("HalfCheetah-v5",)
