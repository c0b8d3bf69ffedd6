"""The paper's experiments by name and budget: each a set of sweeps and a report over them.

``plan(name, budget)`` gives the sweeps (``SweepSpec`` by sub-directory), what is left out and
why, and an estimate of the core-hours; ``reproduce`` runs them through a backend and writes the
report. Budgets:

- ``smoke``: minutes; tiny runs (100-step episodes, 400 steps) of every built algorithm on one
  task, proving the pipeline end to end (CI runs table1's).
- ``small``: what 2 cores do in about a day: fewer tasks, seeds and steps (300k, the fast
  preset), chosen so that the comparison still says something (the paper's learning curves
  separate the algorithms well before 300k on Hopper, Walker2d and HalfCheetah).
- ``full``: the paper's protocol (1M steps, 5 seeds, 1/4/10 demos, the paper preset).

Algorithms that ilfo has not built yet are left out with one line saying so, and join the
experiment once their algo name is in ``ilfo.algos``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from ilfo.experiments.sweep import SweepSpec, expand

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
    "oops_adv": None,  # OOPS with SIL's adversarial cost: not built yet (its own issue)
    "sil": None,  # SIL itself, a Table 1 algo
}
"""Table 4's variants of OOPS+TD3 (keys as data/paper/results.json's ``variant_key``), each a
change of the OOPS reward's settings; None: not built yet."""

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
FULL_CONFIG: dict[str, Any] = {"steps": 1_000_000, "preset": "paper"}

STEPS_PER_CORE_SECOND: dict[str, float] = {
    "oops-td3": 147.0,
    "oops-ddpg": 147.0,
    "oops-sac": 120.0,
    "pwil-td3": 147.0,
    "gaifo-td3": 92.0,
    "opolo": 70.0,
    "firl-fkl": 77.0,
}
"""For the estimate only: half the 2-core loop rates of ``bench/train.py`` (docs/benchmarks.md,
2026-12-01; fast preset, Hopper); the paper preset runs at about a third of the fast one."""


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
    measures_distances: bool = False
    """Whether the report adds Table 3's Wasserstein distances of each run's final rollouts."""
    calibration: CalibrationPlan | None = None
    """The calibration figure's episodes, where the experiment is that figure."""

    @property
    def runs(self) -> int:
        """Training runs (the calibration trains none)."""
        return sum(len(expand(spec)) for spec in self.sweeps.values())

    def core_hours(self) -> float:
        """Estimated core-hours at the measured rates (``STEPS_PER_CORE_SECOND``)."""
        seconds = 0.0
        for spec in self.sweeps.values():
            for run in expand(spec):
                rate = STEPS_PER_CORE_SECOND.get(run.config["algo"], 100.0)
                if run.config.get("preset") == "paper" and run.config["algo"] in (
                    "oops-td3",
                    "oops-ddpg",
                    "pwil-td3",
                ):
                    rate /= 3
                seconds += run.steps / rate
        if self.calibration is not None:  # ~1,500 env + policy steps/s and ~0.1 s per solve
            cal = self.calibration
            seconds += cal.rollouts * ((cal.horizon or 1000) / 1500 + 0.1)
        return seconds / 3600

    def describe(self) -> str:
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
        hours = self.core_hours()
        amount = f"{hours:.1f} core-hours" if hours >= 1 else f"{60 * hours:.1f} core-minutes"
        lines.append(f"  estimated {amount} of compute (rates of docs/benchmarks.md)")
        return "\n".join(lines)


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
        config = SMALL_CONFIG
        left_out.append("the other four tasks: the full budget only")
    else:
        axes = {"env": MUJOCO, "num_demos": (10,), "seed": (0, 1, 2, 3, 4)}
        config = FULL_CONFIG
    sweeps = {
        "default": SweepSpec(algo=("oops-td3",), config=config, **axes),
        "variants": SweepSpec(algo=("oops-td3",), config=config, variants=variants, **axes),
    }
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
    return Plan("table3", budget, {"table3": spec}, tuple(left_out), measures_distances=True)


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
}
"""The experiments ``ilfo reproduce`` runs (the solver-vs-lambda figure is not among them
yet)."""


def reproduce(
    name: str,
    budget: Budget,
    root: str | Path,
    backend_factory: Any,
    *,
    on_change: Any = None,
) -> tuple[Plan, list[Path]]:
    """Run the plan's sweeps in ``root/<sweep>`` (each resumable: run it again to continue)
    and write the report to ``root/report``; returns the plan and the report's files."""
    from ilfo.experiments.backends import run_sweep
    from ilfo.experiments.report import build_report, collect_runs, write_report
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
    for sub, spec in the_plan.sweeps.items():
        sweep = create_sweep(root / sub, spec)
        run_sweep(sweep, backend_factory(), on_change=on_change)
    runs, skipped = collect_runs([root / sub for sub in the_plan.sweeps])
    report = build_report(runs, skipped=[*skipped, *the_plan.left_out])
    return the_plan, write_report(
        report, root / "report", sources=[f"ilfo reproduce {name} --budget {budget}"]
    )
