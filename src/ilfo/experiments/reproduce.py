"""The paper's experiments by name and budget: each a set of sweeps and a report over them.

``plan(name, budget)`` gives the sweeps (``SweepSpec`` by sub-directory), what is left out and
why, and an estimate of the core-hours; ``reproduce`` runs them through a backend and writes the
report. Budgets:

- ``smoke``: minutes; tiny runs (100-step episodes, 400 steps) of every built algorithm on one
  task, proving the pipeline end to end (CI runs table1's).
- ``small``: what 2 cores do in about a day: fewer tasks, seeds and steps (300k, the fast
  preset), chosen so that the comparison still says something (the paper's learning curves
  separate the algorithms well before 300k on Hopper, Walker2d and HalfCheetah). The
  experiments of OOPS+TD3 alone (table4's variants, solvers) take four updates per step, not
  the paper's one: at one, most Hopper seeds are still on their plateau at 300k
  (``SMALL_OOPS_CONFIG``).
- ``full``: the paper's protocol (1M steps, 5 seeds, 1/4/10 demos, the paper preset).

Algorithms that ilfo has not built yet are left out with one line saying so, and join the
experiment once their algo name is in ``ilfo.algos``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from ilfo.experiments.estimates import MEASURE_SECONDS_PER_PAIR, is_on_policy, run_core_seconds
from ilfo.experiments.measures import read_kept, write_distances, write_solvers
from ilfo.experiments.sweep import RUNS_DIR, SweepSpec, expand

Budget = Literal["smoke", "small", "full"]
BUDGETS: tuple[Budget, ...] = ("smoke", "small", "full")

MUJOCO = ("Hopper-v5", "Walker2d-v5", "HalfCheetah-v5", "Ant-v5", "Humanoid-v5")
NEW_ENVS = ("BipedalWalker-v3", "MinitaurBulletEnv-v0", "MinitaurBulletDuckEnv-v0")
TABLE1_ALGOS = ("firl-fkl", "opolo", "sil", "pwil-td3", "oops-ddpg", "oops-td3")
TABLE2_ALGOS = ("opolo", "pwil-td3", "oops-td3")
ABLATIONS: dict[str, dict[str, Any] | None] = {
    "state_only": {"oops": {"atoms": "states"}},
    "w_greedy": {"oops": {"solver": "greedy"}},
    "w_simplex": {"oops": {"solver": "emd"}},
    "lambda_0.005": {"oops": {"reg": 0.005}},
    "lambda_0.1": {"oops": {"reg": 0.1}},
    "lambda_0.5": {"oops": {"reg": 0.5}},
    "w2_l2": {"oops": {"metric": "sqeuclidean"}},
    "w1_l2": {"oops": {"metric": "euclidean"}},
    "w1_cos": {"oops": {"metric": "cosine"}},
}
"""Table 4's variants of OOPS+TD3 (keys as data/paper/results.json's ``variant_key``), each a
change of the OOPS reward's settings; None: not built yet."""
TABLE4_ALGOS: tuple[str, ...] = ("oops-adv-td3", "sil")
"""Table 4's other rows, algos of their own (OOPS_adv, SIL): the report compares each with
OOPS+TD3 (``report.TABLE4_ALGOS``)."""

SMOKE_CONFIG: dict[str, Any] = {
    "horizon": 100,
    "start_steps": 200,
    "steps": 400,
    "eval_every": 200,
    "eval_episodes": 1,
    "checkpoint_every": 200,
    "preset": "fast",
    "replay_capacity": 5000,
}
"""Tiny runs: seconds of training each (their scores mean nothing)."""
SMALL_CONFIG: dict[str, Any] = {"steps": 300_000, "preset": "fast"}
SMALL_OOPS_CONFIG: dict[str, Any] = {**SMALL_CONFIG, "updates_per_step": 4}
"""The small budget of the experiments that compare OOPS+TD3 with itself (table4, solvers).
With the paper's one update per step OOPS+TD3 on Hopper sits on its plateau (standing,
falling) to 300k for most seeds: 0.17 +- 0.25 of the expert over seeds 0-7, one above 0.8, so
the variants would be compared on plateaus; with four, 0.85 +- 0.26, seven of eight above 0.8
(``bench/learning.py``; docs/benchmarks.md as of commit 446cbed, "two updates per
environment step"), at about three times the compute per step.
On-policy algos (sil) keep one: ``updates_per_step`` does not apply to them."""
FULL_CONFIG: dict[str, Any] = {"steps": 1_000_000, "preset": "paper"}


@dataclass(frozen=True)
class CalibrationPlan:
    """What the calibration experiment rolls out: per env, each noise level's episodes."""

    envs: tuple[str, ...]
    noise_levels: tuple[float, ...]
    episodes: int
    horizon: int | None = None
    """Episode length (None: the expert's, 1,000)."""

    @property
    def rollouts(self) -> int:
        return len(self.envs) * (len(self.noise_levels) + 2) * self.episodes


@dataclass(frozen=True)
class Plan:
    """What an experiment at a budget runs."""

    name: str
    budget: Budget
    sweeps: dict[str, SweepSpec]
    """Sweep specs by sub-directory name."""
    left_out: tuple[str, ...]
    """One line per algorithm or variant not run, and why."""
    measures: tuple[Literal["distances", "solvers"], ...] = ()
    """What the report adds from each run's final rollouts: Table 3's distances, the solver
    figure's transport costs."""
    measure_episodes: int = 10
    """Final rollouts per run, and expert trajectories, that ``measures`` use (the paper: 10)."""
    calibration: CalibrationPlan | None = None
    """The calibration figure's episodes, where the experiment is that figure."""

    @property
    def runs(self) -> int:
        """Training runs (the calibration trains none)."""
        return sum(len(expand(spec)) for spec in self.sweeps.values())

    def measure_hours(self, root: Path | None = None) -> float:
        """Estimated core-hours of ``measures`` (``MEASURE_SECONDS_PER_PAIR`` at 1,000-step
        episodes; a pair's solves scale about as the square of the episodes' length). With
        ``root``, the experiment's directory, only the pairs its runs have not kept."""
        seconds = 0.0
        for sub, spec in self.sweeps.items():
            for run in expand(spec):
                length = (run.config.get("horizon") or 1000) / 1000
                for measure in self.measures:
                    pairs = self.measure_episodes**2
                    if root is not None:
                        pairs -= _pairs_kept(root / sub / RUNS_DIR / run.name, measure, pairs)
                    seconds += pairs * MEASURE_SECONDS_PER_PAIR[measure] * length**2
        return seconds / 3600

    def core_hours(self, root: Path | None = None) -> float:
        """Estimated core-hours at the measured rates (``estimates.run_core_seconds``: each
        run's steps and its fixed cost), the measures included. With ``root``, the
        experiment's directory, only what is left: the steps past each run's newest
        checkpoint (what a resume continues from, paying the fixed cost again; a finished
        run none) and the measures' pairs not kept."""
        from ilfo.training.run_dir import checkpoint_steps

        seconds = 3600 * self.measure_hours(root)
        for sub, spec in self.sweeps.items():
            for run in expand(spec):
                steps = run.steps
                if root is not None:
                    kept = checkpoint_steps(root / sub / RUNS_DIR / run.name)
                    steps -= min(kept[-1][0], run.steps) if kept else 0
                estimate = run_core_seconds(run.config, steps, unmeasured_rate=100.0)
                seconds += estimate or 0.0  # never None: unmeasured_rate stands in
        if self.calibration is not None:  # ~1,500 env + policy steps/s and ~0.1 s per solve
            cal = self.calibration
            seconds += cal.rollouts * ((cal.horizon or 1000) / 1500 + 0.1)
        return seconds / 3600

    def describe(self, root: Path | None = None) -> str:
        """The plan in a few lines; with ``root``, the experiment's directory, also what of
        the estimate is left there."""
        lines = [f"{self.name} at the {self.budget} budget: {self.runs} training runs"]
        if self.calibration is not None:
            cal = self.calibration
            lines.append(
                f"  calibration: {', '.join(cal.envs)}; noise levels {list(cal.noise_levels)} "
                f"(and zero, random actions) x {cal.episodes} episodes of "
                f"{cal.horizon or 1000} steps: {cal.rollouts} rollouts"
            )
        for sub, spec in self.sweeps.items():
            variants = f"; variants {', '.join(spec.variants)}" if spec.variants else ""
            lines.append(
                f"  {sub}: {', '.join(spec.env)} x {', '.join(spec.algo)} x demos "
                f"{list(spec.num_demos)} x seeds {list(spec.seed)}{variants}; "
                f"{dict(spec.config)}"
            )
        lines += [f"  left out: {line}" for line in self.left_out]
        measures = ""
        if self.measures:
            measures = f", {_amount(self.measure_hours())} of them measuring the final rollouts"
        total = self.core_hours()
        lines.append(
            f"  estimated {_amount(total)} of compute{measures} (rates of docs/benchmarks.md)"
        )
        if root is not None and self.calibration is None:
            left = self.core_hours(root)
            if left < total:
                lines.append(f"  {_amount(left)} of it left: {root} holds the rest")
        return "\n".join(lines)


def _amount(hours: float) -> str:
    return f"{hours:.1f} core-hours" if hours >= 1 else f"{60 * hours:.1f} core-minutes"


def _pairs_kept(run_dir: Path, measure: str, total: int) -> int:
    """How many of a run's ``total`` pairs of ``measure`` its directory keeps: all where the
    measure is written, else those of its partial file (0 where that is damaged). For the
    estimate only: a measure of an earlier final policy is counted, though measured again."""
    from ilfo.training.run_dir import DISTANCES_FILE, SOLVERS_FILE, partial_measure_file

    name = {"distances": DISTANCES_FILE, "solvers": SOLVERS_FILE}[measure]
    if read_kept(run_dir / name, "values") is not None:
        return total
    partial = read_kept(run_dir / partial_measure_file(name), "pairs")
    return 0 if partial is None else min(total, len(partial[1]))


def _built(algos: tuple[str, ...]) -> tuple[tuple[str, ...], list[str]]:
    from ilfo.algos import ALGOS

    built = tuple(a for a in algos if a in ALGOS)
    missing = [
        f"{a}: not built yet in ilfo (runs once its algo lands)" for a in algos if a not in ALGOS
    ]
    return built, missing


def _smoke_demos(env: str) -> dict[str, Any]:
    """Smoke runs of Hopper imitate the bundled scripted rollouts (no expert needed)."""
    from ilfo.paths import bundled_demos

    return {"demos": str(bundled_demos("Hopper-v5-scripted"))} if env == "Hopper-v5" else {}


def plan(name: str, budget: Budget) -> Plan:
    """The sweeps of experiment ``name`` at ``budget`` (see the module)."""
    if budget not in BUDGETS:
        raise ValueError(f"budget must be one of {', '.join(BUDGETS)}, got {budget!r}")
    if name not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}")
    return EXPERIMENTS[name](budget)


def _table1(budget: Budget) -> Plan:
    algos, left_out = _built(TABLE1_ALGOS)
    if budget == "smoke":
        spec = SweepSpec(
            env=("Hopper-v5",), algo=algos, config={**SMOKE_CONFIG, **_smoke_demos("Hopper-v5")}
        )
    elif budget == "small":
        spec = SweepSpec(
            env=MUJOCO[:3], algo=algos, num_demos=(1,), seed=(0, 1, 2), config=SMALL_CONFIG
        )
        left_out.append("Ant-v5, Humanoid-v5 and 4 or 10 demos: the full budget only")
    else:
        spec = SweepSpec(
            env=MUJOCO, algo=algos, num_demos=(1, 4, 10), seed=(0, 1, 2, 3, 4), config=FULL_CONFIG
        )
    return Plan("table1", budget, {"table1": spec}, tuple(left_out))


def _table2(budget: Budget) -> Plan:
    algos, left_out = _built(TABLE2_ALGOS)
    if budget == "smoke":
        spec = SweepSpec(env=("BipedalWalker-v3",), algo=algos, config=SMOKE_CONFIG)
    elif budget == "small":
        spec = SweepSpec(env=NEW_ENVS, algo=algos, num_demos=(1,), seed=(0, 1), config=SMALL_CONFIG)
        left_out.append("4 or 10 demos: the full budget only")
    else:
        spec = SweepSpec(
            env=NEW_ENVS, algo=algos, num_demos=(1, 4, 10), seed=(0, 1, 2, 3, 4), config=FULL_CONFIG
        )
    return Plan("table2", budget, {"table2": spec}, tuple(left_out))


def _table4(budget: Budget) -> Plan:
    variants = {k: v for k, v in ABLATIONS.items() if v is not None}
    left_out = [f"{k}: not built yet in ilfo" for k, v in ABLATIONS.items() if v is None]
    if budget == "smoke":
        axes: dict[str, Any] = {"env": ("Hopper-v5",), "num_demos": (1,), "seed": (0,)}
        config = {**SMOKE_CONFIG, **_smoke_demos("Hopper-v5")}
        variants = {k: variants[k] for k in ("state_only", "w_greedy", "w1_cos")}
        left_out.append("the other variants: the small and full budgets")
    elif budget == "small":
        axes = {"env": ("Hopper-v5",), "num_demos": (10,), "seed": (0, 1)}
        config = SMALL_OOPS_CONFIG
        left_out.append("the other four tasks: the full budget only")
    else:
        axes = {"env": MUJOCO, "num_demos": (10,), "seed": (0, 1, 2, 3, 4)}
        config = FULL_CONFIG
    sweeps = {
        "default": SweepSpec(algo=("oops-td3",), config=config, **axes),
        "variants": SweepSpec(algo=("oops-td3",), config=config, variants=variants, **axes),
    }
    algos, not_built = _built(TABLE4_ALGOS)
    left_out[:0] = not_built
    off_policy = tuple(a for a in algos if not is_on_policy(a))
    on_policy = tuple(a for a in algos if is_on_policy(a))
    if off_policy:
        sweeps["algos"] = SweepSpec(algo=off_policy, config=config, **axes)
    if on_policy:  # SIL's TRPO: the same runs, but updates per step do not apply to it
        learns_per_batch = {k: v for k, v in config.items() if k != "updates_per_step"}
        sweeps["on_policy"] = SweepSpec(algo=on_policy, config=learns_per_batch, **axes)
    return Plan("table4", budget, sweeps, tuple(left_out))


def _table3(budget: Budget) -> Plan:
    algos, left_out = _built(TABLE3_ALGOS)
    if budget == "smoke":
        spec = SweepSpec(
            env=("Hopper-v5",),
            algo=algos,
            num_demos=(10,),
            config={**SMOKE_CONFIG, **_smoke_demos("Hopper-v5")},
        )
    elif budget == "small":
        spec = SweepSpec(
            env=("Hopper-v5", "Walker2d-v5"),
            algo=algos,
            num_demos=(10,),
            seed=(0,),
            config=SMALL_CONFIG,
        )
        left_out.append("HalfCheetah-v5, Ant-v5, Humanoid-v5: the full budget only")
    else:
        spec = SweepSpec(
            env=MUJOCO, algo=algos, num_demos=(10,), seed=(0, 1, 2, 3, 4), config=FULL_CONFIG
        )
    episodes = 2 if budget == "smoke" else 10
    return Plan("table3", budget, {"table3": spec}, tuple(left_out), ("distances",), episodes)


def _solvers(budget: Budget) -> Plan:
    left_out = []
    if budget == "smoke":
        spec = SweepSpec(
            algo=("oops-td3",),
            num_demos=(10,),
            config={**SMOKE_CONFIG, **_smoke_demos("Hopper-v5")},
        )
    elif budget == "small":
        spec = SweepSpec(algo=("oops-td3",), num_demos=(10,), config=SMALL_OOPS_CONFIG)
        left_out.append("the other four tasks (the appendix's figure): the full budget")
    else:
        spec = SweepSpec(env=MUJOCO, algo=("oops-td3",), num_demos=(10,), config=FULL_CONFIG)
    episodes = 2 if budget == "smoke" else 10
    return Plan("solvers", budget, {"solvers": spec}, tuple(left_out), ("solvers",), episodes)


TABLE3_ALGOS = ("opolo", "pwil-td3", "oops-td3")


def _calibration(budget: Budget) -> Plan:
    from ilfo.experiments.calibration import PAPER_NOISE_LEVELS

    if budget == "smoke":
        cal = CalibrationPlan(("Hopper-v5",), (0.0, 0.5), 1, horizon=100)
        left_out = ["the other tasks and noise levels: the small and full budgets"]
    elif budget == "small":
        cal = CalibrationPlan(MUJOCO[:3], PAPER_NOISE_LEVELS[::3], 3)
        left_out = ["Ant-v5, Humanoid-v5 and every 0.1 of l: the full budget"]
    else:
        cal = CalibrationPlan(MUJOCO, PAPER_NOISE_LEVELS, 5)
        left_out = []
    return Plan("calibration", budget, {}, tuple(left_out), calibration=cal)


"""Table 3's agents: the paper's top three of Table 1, trained from 10 demos."""

EXPERIMENTS = {
    "table1": _table1,
    "table2": _table2,
    "table3": _table3,
    "table4": _table4,
    "calibration": _calibration,
    "solvers": _solvers,
}
"""The experiments ``ilfo reproduce`` runs: the paper's Tables 1-4, its calibration figure and
its solver-vs-lambda figure."""


def reproduce(
    name: str,
    budget: Budget,
    root: str | Path,
    backend_factory: Any,
    *,
    on_change: Any = None,
    log: Callable[[str], None] = print,
) -> tuple[Plan, list[Path]]:
    """Run the plan's sweeps in ``root/<sweep>`` (each resumable: run it again to continue)
    and write the report to ``root/report``; returns the plan and the report's files.
    ``log`` gets a line as each run's final rollouts are measured (minutes each)."""
    from ilfo.experiments.backends import run_sweeps
    from ilfo.experiments.report import build_report, collect_runs
    from ilfo.experiments.report_tables import write_report
    from ilfo.experiments.sweep import create_sweep

    the_plan = plan(name, budget)
    root = Path(root)
    if the_plan.calibration is not None:
        from ilfo.experiments.calibration import calibrate, write_calibration

        cal = the_plan.calibration
        results = {
            env: calibrate(env, cal.noise_levels, cal.episodes, horizon=cal.horizon)
            for env in cal.envs
        }
        return the_plan, write_calibration(results, root / "report")
    sweeps = [create_sweep(root / sub, spec) for sub, spec in the_plan.sweeps.items()]
    if sweeps:  # one queue: a core that one sweep's last runs leave free takes the next's
        run_sweeps(sweeps, backend_factory(), on_change=on_change)
    runs, skipped = collect_runs([root / sub for sub in the_plan.sweeps])
    report = build_report(runs, skipped=[*skipped, *the_plan.left_out])
    out = root / "report"
    written = write_report(report, out, sources=[f"ilfo reproduce {name} --budget {budget}"])
    if "distances" in the_plan.measures:
        written += write_distances(runs, out, the_plan.measure_episodes, log=log)
    if "solvers" in the_plan.measures:
        written += write_solvers(runs, out, the_plan.measure_episodes, log=log)
    return the_plan, written
