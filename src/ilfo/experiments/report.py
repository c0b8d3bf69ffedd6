"""Reports over runs: the paper's final performance per task x algo x demos (mean +- std over
seeds), rliable's aggregates with bootstrap confidence intervals beside it, the paper's numbers
beside both, and learning curves and performance profiles as figures.

``collect_runs`` finds runs (sweep directories, run directories, or folders holding either);
``build_report`` groups them into cells; ``write_report`` writes ``report.md``, ``cells.csv``,
``aggregates.csv`` and PNG figures (``report_figures``).

The final performance of a run is the paper's: its last evaluation (``eval_episodes``
deterministic fixed-horizon episodes), normalised by the demos' mean return
(``eval_score_norm``). The std over seeds is the population std (NumPy's default), as the
paper does not say which it uses.
"""

from __future__ import annotations

import functools
import json
import math
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ilfo.experiments import stats
from ilfo.paper import PaperCell, paper_ablation, paper_score
from ilfo.training.run_labels import run_variant, shared_settings, training_settings

SCORE = "eval_score_norm"
RETURN = "eval_return_norm"


TABLE4_ALGOS: dict[str, str] = {"oops-adv-td3": "oops_adv", "sil": "sil"}
"""Algos that are rows of the paper's Table 4 (by its variant key) though not changes of
OOPS's settings: a report compares each with OOPS+TD3 on the same task and demos."""


@dataclass(frozen=True)
class RunResult:
    """What a report reads of one run."""

    run_dir: Path
    env: str
    algo: str
    num_demos: int
    seed: int
    variant: str | None
    steps: int
    """The run's budget."""
    curve_steps: np.ndarray = field(repr=False)
    curve_scores: np.ndarray = field(repr=False)
    final_return: float
    """The last evaluation's standard return (stops at the first fall), normalised."""
    shipped_demos: bool = True
    """Whether it imitated the env's shipped expert demos (the only ones the paper's numbers
    can be compared with)."""
    trained_step: int | None = None
    """The step its last episode reached (metrics.csv's last row); None: its last evaluation's."""
    settings: tuple[str, ...] = ()
    """Where it was trained otherwise than ``ilfo train``'s defaults for its task and algo (the
    paper's protocol), e.g. ``("fast preset", "4 updates/step")``: what the cell key does not
    say (its reward settings and observations are its variant, its demos ``shipped_demos``)."""

    @property
    def final_step(self) -> int:
        return int(self.curve_steps[-1])

    @property
    def final_score(self) -> float:
        return float(self.curve_scores[-1])

    @property
    def finished(self) -> bool:
        """Trained to its budget: its last episode, not its last evaluation (a budget that is
        not a multiple of ``eval_every`` ends past the last one)."""
        reached = self.final_step if self.trained_step is None else self.trained_step
        return reached >= self.steps


def _is_run_dir(path: Path) -> bool:
    return (path / "config.json").is_file() and (path / "metrics.csv").is_file()


def collect_runs(paths: Iterable[str | Path]) -> tuple[list[RunResult], list[str]]:
    """The runs under ``paths`` (each a sweep directory, a run directory, or a folder searched
    for both), and a line for each run left out (no evaluation yet, unreadable)."""
    from ilfo.experiments.sweep import MANIFEST_FILE, RUNS_DIR, open_sweep

    found: dict[Path, str | None] = {}  # run dir -> variant
    variants: dict[Path, dict[str, str | None]] = {}  # sweep root -> run name -> variant

    def variants_of(root: Path) -> dict[str, str | None]:
        if root not in variants:
            variants[root] = {run.name: run.variant for run in open_sweep(root).runs}
        return variants[root]

    for given in map(Path, paths):
        if not given.exists():
            raise FileNotFoundError(f"{given}: no such sweep or run directory")
        sweeps = [given] if (given / MANIFEST_FILE).is_file() else []
        sweeps += [p.parent for p in given.rglob(MANIFEST_FILE) if p.parent != given]
        for root in sweeps:
            for name, variant in variants_of(root).items():
                if (root / RUNS_DIR / name).is_dir():
                    found.setdefault((root / RUNS_DIR / name).resolve(), variant)
        candidates = [given] if _is_run_dir(given) else []
        candidates += [p.parent for p in given.rglob("config.json")]
        for path in candidates:
            if not _is_run_dir(path):
                continue
            root = path.parent.parent
            if path.parent.name == RUNS_DIR and (root / MANIFEST_FILE).is_file():
                # A sweep's run (given itself, or its runs/ folder): its variant is the manifest's.
                if path.name in variants_of(root):
                    found.setdefault(path.resolve(), variants_of(root)[path.name])
            else:
                found.setdefault(path.resolve(), None)
    runs, skipped = [], []
    for run_dir, variant in sorted(found.items()):
        try:
            result = read_run(run_dir, variant)
        except (OSError, ValueError, KeyError) as err:
            skipped.append(f"{run_dir}: unreadable ({err})")
            continue
        if result is None:
            skipped.append(f"{run_dir}: no evaluation with a normalised score yet")
        else:
            runs.append(result)
    return runs, skipped


def read_run(run_dir: str | Path, variant: str | None = None) -> RunResult | None:
    """A run's evaluations (None if it has none with a normalised score yet)."""
    from ilfo.training import read_metrics, read_run_config
    from ilfo.training.run_dir import read_demos_record

    run_dir = Path(run_dir)
    config = read_run_config(run_dir)
    env = str(config["env"])
    record = read_demos_record(run_dir)
    shipped = imitates_shipped_demos(config.get("demos"), env) and _same_file_as_shipped(
        record, env
    )
    # Runs that observed otherwise than the default are not its cell (nor a sweep variant's),
    # nor are runs whose reward differs from the algo's (a sweep's variant already says how).
    variant = run_variant(config, run_dir / "config.json", variant)
    if not (run_dir / "metrics.csv").is_file():  # a sweep's run before its first episode
        return None
    all_rows = read_metrics(run_dir)
    rows = [r for r in all_rows if r.get(SCORE)]
    if not rows:
        return None
    return RunResult(
        run_dir=run_dir,
        env=str(config["env"]),
        algo=str(config["algo"]),
        num_demos=int(config.get("num_demos", 1)),
        seed=int(config.get("seed", 0)),
        variant=variant,
        steps=int(config["steps"]),
        curve_steps=np.array([int(r["step"]) for r in rows]),
        curve_scores=np.array([float(r[SCORE]) for r in rows]),
        final_return=float(rows[-1][RETURN]) if rows[-1].get(RETURN) else math.nan,
        shipped_demos=shipped,
        settings=training_settings(config, run_dir / "config.json"),
        trained_step=int(all_rows[-1]["step"]),
    )


def _same_file_as_shipped(record: dict[str, Any] | None, env: str) -> bool:
    """Whether a run's ``demos.json`` names the demo file that ``env`` ships now, not one of an
    expert re-exported since; True where that cannot be told (a run older than the record,
    no shipped file here to compare with)."""
    if record is None:
        return True
    shipped = _shipped_demos_sha256(env)
    return shipped is None or record.get("sha256") == shipped


@functools.cache
def _shipped_demos_sha256(env: str) -> str | None:
    from ilfo.files import file_sha256
    from ilfo.training.build import default_demos_path

    path = default_demos_path(env)
    return file_sha256(path) if path.is_file() else None


STRONG_EXPERT = 0.9
"""The fraction of the paper's expert return from which a shipped expert counts as the
paper's equal (issue 25's bar); below it, the report says so beside the cell's verdict."""


@functools.cache
def shipped_expert_fraction(env: str) -> float | None:
    """The shipped expert's demo return over the paper's expert's (``card.json``), or None."""
    from ilfo.experts import CARD_FILE
    from ilfo.training.build import default_demos_path

    card = default_demos_path(env).parent / CARD_FILE
    if not card.is_file():
        return None
    fraction = json.loads(card.read_text()).get("fraction_of_paper_expert")
    return None if fraction is None else float(fraction)


def imitates_shipped_demos(demos: str | None, env: str) -> bool:
    """Whether a run's ``demos`` setting is the env's shipped expert demos: None (the default)
    or a path to them as this repository lays them out (``.../data/experts/<env>/demos.npz``,
    relative or absolute, e.g. ``--demos data/experts/Walker2d-v5/demos.npz``)."""
    from ilfo.training.build import default_demos_path

    if demos is None:
        return True
    return Path(demos).parts[-4:] == default_demos_path(env).parts[-4:]


CellKey = tuple[str, str, int, "str | None"]


@dataclass(frozen=True)
class Cell:
    """The runs of one task x algo x demos x variant, with their statistics."""

    env: str
    algo: str
    num_demos: int
    variant: str | None
    runs: tuple[RunResult, ...]
    iqm: stats.Interval
    paper: PaperCell | None
    """The paper's number for this cell (Tables 1-2; Table 4 for a variant)."""

    @property
    def key(self) -> CellKey:
        return (self.env, self.algo, self.num_demos, self.variant)

    @property
    def scores(self) -> np.ndarray:
        return np.array([r.final_score for r in self.runs])

    @property
    def mean(self) -> float:
        return float(self.scores.mean())

    @property
    def std(self) -> float:
        return float(self.scores.std())

    @property
    def finished(self) -> bool:
        return all(r.finished for r in self.runs)

    @property
    def settings(self) -> tuple[str, ...]:
        """The training settings, other than the defaults, that all its runs share."""
        return shared_settings([r.settings for r in self.runs])

    @property
    def mixed_settings(self) -> dict[str, tuple[int, ...]]:
        """Settings that only some of its runs have, each with those runs' seeds: runs trained
        otherwise, averaged as if they were seeds of one setting."""
        shared = set(self.settings)
        mixed: dict[str, tuple[int, ...]] = {}
        for run in self.runs:
            for label in run.settings:
                if label not in shared:
                    mixed[label] = (*mixed.get(label, ()), run.seed)
        return mixed

    @property
    def settings_text(self) -> str:
        """``settings``, then any ``mixed_settings`` with their seeds."""
        parts = list(self.settings)
        parts += [
            f"{label} (seeds {' '.join(map(str, seeds))} only)"
            for label, seeds in self.mixed_settings.items()
        ]
        return "; ".join(parts)

    @property
    def expert_fraction(self) -> float | None:
        """How good the expert behind its demos is: the shipped expert's return as a fraction
        of the paper's expert's (its card's ``fraction_of_paper_expert``); None where its runs
        imitated other demos or the card does not say. Below ``STRONG_EXPERT``, its demos
        are easier to match than the paper's and normalised scores flatter ilfo."""
        if not all(r.shipped_demos for r in self.runs):
            return None
        return shipped_expert_fraction(self.env)

    @property
    def versus_paper(self) -> str:
        """``within`` / ``above`` / ``below`` the paper's mean +- 2 std, ``other demos`` where
        runs imitated other demos than the shipped expert's, ``non-finite score`` where a run's
        final evaluation is NaN or infinite, or empty (no paper number)."""
        if self.paper is None or self.paper.std is None or self.variant is not None:
            return ""
        if not all(r.shipped_demos for r in self.runs):
            return "other demos"
        if not np.isfinite(self.mean):  # a run's evaluation was NaN or infinite (diverged)
            return "non-finite score"
        gap = self.mean - self.paper.mean
        if abs(gap) <= 2 * self.paper.std:
            return "within"
        return "above" if gap > 0 else "below"


@dataclass(frozen=True)
class Report:
    cells: tuple[Cell, ...]
    skipped: tuple[str, ...]
    resamples: int

    def cell(self, env: str, algo: str, num_demos: int, variant: str | None = None) -> Cell:
        for c in self.cells:
            if c.key == (env, algo, num_demos, variant):
                return c
        raise KeyError((env, algo, num_demos, variant))

    def percent_difference(self, cell: Cell) -> float | None:
        """A variant's mean final score relative to its default (the same task, algo and
        demos without a variant), in percent, as the paper's Table 4; for an algo that is a
        row of Table 4 (``TABLE4_ALGOS``), relative to OOPS+TD3's; None without one."""
        base = self.base_cell(cell)
        if base is None:
            return None
        return 100 * (cell.mean - base.mean) / abs(base.mean) if base.mean else None

    def base_cell(self, cell: Cell) -> Cell | None:
        """What ``percent_difference`` compares a cell with: for a variant, the same task, algo
        and demos without one; for an algo of Table 4, OOPS+TD3's; None if absent."""
        if cell.variant is None and cell.algo not in TABLE4_ALGOS:
            return None
        base_algo = cell.algo if cell.variant else "oops-td3"
        try:
            return self.cell(cell.env, base_algo, cell.num_demos)
        except KeyError:
            return None

    def groups(self) -> list[tuple[str, int, str | None]]:
        """(algo, num_demos, variant) in order of appearance."""
        return list(dict.fromkeys((c.algo, c.num_demos, c.variant) for c in self.cells))

    def task_scores(self, algo: str, num_demos: int, variant: str | None, envs: Sequence[str]):
        """(runs, tasks) final scores of a group on ``envs`` (NaN for missing runs)."""
        columns = []
        for env in envs:
            try:
                columns.append(self.cell(env, algo, num_demos, variant).scores)
            except KeyError:
                columns.append(np.array([]))
        width = max([c.size for c in columns] + [1])
        out = np.full((width, len(envs)), np.nan)
        for t, column in enumerate(columns):
            out[: column.size, t] = column
        return out

    def envs_of(self, algo: str, num_demos: int, variant: str | None) -> list[str]:
        return [
            c.env
            for c in self.cells
            if (c.algo, c.num_demos, c.variant) == (algo, num_demos, variant)
        ]


def build_report(
    runs: Sequence[RunResult],
    *,
    skipped: Sequence[str] = (),
    resamples: int = 2000,
    seed: int = 0,
) -> Report:
    """Group runs into cells and compute each cell's statistics (``skipped``: the lines of
    runs left out, for the report to list)."""
    grouped: dict[CellKey, list[RunResult]] = {}
    for run in runs:
        grouped.setdefault((run.env, run.algo, run.num_demos, run.variant), []).append(run)
    cells = []
    for (env, algo, num_demos, variant), members in grouped.items():
        members.sort(key=lambda r: r.seed)
        cell_name = f"{env} {algo} demos {num_demos}{f' {variant}' if variant else ''}"
        seeds = [r.seed for r in members]
        if len(set(seeds)) != len(seeds):
            warnings.warn(
                f"{cell_name}: seeds {seeds} repeat (the same runs found twice?); each counts",
                stacklevel=2,
            )
        scores = np.array([r.final_score for r in members])
        interval = stats.stratified_bootstrap(scores, stats.iqm, resamples=resamples, seed=seed)
        paper = (
            paper_score(env, algo, num_demos)
            if variant is None
            else (paper_ablation(env, variant) if algo == "oops-td3" else None)
        )
        cell = Cell(env, algo, num_demos, variant, tuple(members), interval, paper)
        if cell.mixed_settings:
            warnings.warn(
                f"{cell_name}: its runs were trained with different settings "
                f"({', '.join(sorted(cell.mixed_settings))}); they are averaged as seeds of one "
                "cell",
                stacklevel=2,
            )
        cells.append(cell)
    order = {env: k for k, env in enumerate(dict.fromkeys(r.env for r in runs))}
    cells.sort(key=lambda c: (order[c.env], c.num_demos, c.algo, c.variant or ""))
    return Report(tuple(cells), tuple(skipped), resamples)


# -------------------------------------------------------------------------------- writing
