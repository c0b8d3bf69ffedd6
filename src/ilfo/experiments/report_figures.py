"""A report's figures: learning curves per task and performance profiles per demo count
(``report_tables.write_report`` writes them), and ``finish_figure``, which every figure of ``ilfo
report`` and ``ilfo reproduce`` ends with.

A performance profile compares algorithms on the same tasks: it is drawn over the tasks that
``profile_selection`` chooses, with the algorithms run on every one of them, and the report
says which were left out."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilfo.experiments import stats

if TYPE_CHECKING:
    from ilfo.experiments.report import Report, RunResult

Group = tuple[str, int, "str | None"]
"""(algo, num_demos, variant): a report's group of cells, one per task."""


def group_label(algo: str, num_demos: int, variant: str | None) -> str:
    """How a figure's legend names a group: "oops-td3 [lambda_0.1], 4 demos"."""
    return f"{algo}{f' [{variant}]' if variant else ''}, {num_demos} demo{'s' * (num_demos > 1)}"


@dataclass(frozen=True)
class ProfileSelection:
    """What one performance profile draws, and what it leaves out."""

    num_demos: int
    tasks: tuple[str, ...]
    """The tasks it is drawn over, in the report's order."""
    groups: tuple[Group, ...]
    """The groups drawn: those with runs on every one of ``tasks``."""
    left_out: tuple[tuple[Group, tuple[str, ...]], ...]
    """The groups not drawn, each with the tasks it has runs on."""
    tasks_left_out: tuple[str, ...]
    """Tasks of drawn groups outside ``tasks`` (no other drawn group covers them)."""


def profile_selection(report: Report, num_demos: int) -> ProfileSelection:
    """The tasks and groups of ``num_demos``'s profile: of the groups' task sets, the one that
    the most (group, task) pairs are drawn on when only the groups with runs on all its tasks
    are (ties: more tasks, then the first group's), so that every curve is over the same tasks
    and a group run on a task or two does not empty the profile of the others."""
    groups = [g for g in report.groups() if g[1] == num_demos]
    covers = {g: report.envs_of(*g) for g in groups}
    order = list(dict.fromkeys(c.env for c in report.cells))

    def drawn(tasks: frozenset[str]) -> list[Group]:
        return [g for g in groups if tasks <= set(covers[g])]

    candidates = list(dict.fromkeys(frozenset(envs) for envs in covers.values()))
    best = max(candidates, key=lambda t: (len(drawn(t)) * len(t), len(t)))  # first on ties
    chosen = drawn(best)
    extra = {env for g in chosen for env in covers[g]} - best
    return ProfileSelection(
        num_demos=num_demos,
        tasks=tuple(env for env in order if env in best),
        groups=tuple(chosen),
        left_out=tuple((g, tuple(covers[g])) for g in groups if g not in chosen),
        tasks_left_out=tuple(env for env in order if env in extra),
    )


def profile_lines(report: Report) -> list[str]:
    """The report's lines saying what each profile is drawn over and what it left out."""
    lines = []
    for demos in sorted({c.num_demos for c in report.cells}):
        chosen = profile_selection(report, demos)
        line = (
            f"- Performance profile, {demos} demo{'s' * (demos > 1)}: over "
            f"{', '.join(chosen.tasks)}, the algos with runs on every one of them"
        )
        if chosen.left_out:
            dropped = "; ".join(
                f"{group_label(*g)} (run on {', '.join(envs)})" for g, envs in chosen.left_out
            )
            line += f"; left out: {dropped}"
        if chosen.tasks_left_out:
            line += f"; tasks left out: {', '.join(chosen.tasks_left_out)}"
        lines.append(line + ".")
    return lines


def _curve_band(run_results: Sequence[RunResult], resamples: int):
    """Common steps, the mean over seeds and its pointwise 95% bootstrap band."""
    last = min(r.final_step for r in run_results)
    steps = run_results[0].curve_steps[run_results[0].curve_steps <= last]
    values = np.stack([np.interp(steps, r.curve_steps, r.curve_scores) for r in run_results])
    mean = values.mean(axis=0)
    if len(run_results) < 2:
        return steps, mean, mean, mean
    rng = np.random.default_rng(0)
    picks = rng.integers(0, len(run_results), size=(resamples, len(run_results)))
    means = values[picks].mean(axis=1)
    low, high = np.percentile(means, [2.5, 97.5], axis=0)
    return steps, mean, low, high


def plot_curves(report: Report, out: Path) -> list[Path]:
    """``curves_<env>.png`` per task: each cell's mean over seeds with a 95% bootstrap band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures = []
    for env in dict.fromkeys(c.env for c in report.cells):
        fig, ax = plt.subplots(figsize=(6, 4))
        for c in (c for c in report.cells if c.env == env):
            steps, mean, low, high = _curve_band(c.runs, min(report.resamples, 1000))
            n = len(c.runs)
            label = f"{group_label(c.algo, c.num_demos, c.variant)} ({n} seed{'s' * (n != 1)})"
            ax.plot(steps, mean, label=label)
            ax.fill_between(steps, low, high, alpha=0.2)
        title = f"{env}: mean over seeds, 95% bootstrap band"
        path = out / f"curves_{env}.png"
        figures.append(finish_figure(fig, ax, title, "environment steps", "normalised score", path))
    return figures


def finish_figure(
    fig: Any,
    ax: Any,
    title: str,
    xlabel: str,
    ylabel: str,
    path: Path,
    *,
    legend_below: bool = False,
) -> Path:
    """Label, save and close a report figure (every figure of ``ilfo report`` and
    ``ilfo reproduce``); ``legend_below``: the legend under the axes, off the curves (for
    figures whose curves fill the axes, as a profile's do)."""
    import matplotlib.pyplot as plt

    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if legend_below:
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2)
    else:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")  # keeps a legend outside the axes
    plt.close(fig)
    return path


def plot_profiles(report: Report, out: Path) -> list[Path]:
    """``profile_<demos>demos.png`` per demo count: the groups of ``profile_selection``, each's
    fraction of runs above each score with a 95% stratified-bootstrap band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures = []
    taus = np.linspace(0.0, 1.25, 101)
    for demos in sorted({c.num_demos for c in report.cells}):
        chosen = profile_selection(report, demos)
        fig, ax = plt.subplots(figsize=(6, 4))
        for algo, _, variant in chosen.groups:
            scores = report.task_scores(algo, demos, variant, chosen.tasks)
            profile, low, high = stats.performance_profile_band(
                scores, taus, resamples=min(report.resamples, 1000)
            )
            ax.plot(taus, profile, label=group_label(algo, demos, variant))
            ax.fill_between(taus, low, high, alpha=0.2)
        tasks = len(chosen.tasks)
        title = f"Performance profile, {demos} demo{'s' * (demos > 1)}, {tasks} task"
        title += "s" * (tasks > 1)
        path = out / f"profile_{demos}demos.png"
        ylabel = "fraction of runs with score > tau"
        figures.append(
            finish_figure(fig, ax, title, "normalised score tau", ylabel, path, legend_below=True)
        )
    return figures
