"""A ``Report`` written out: its cells, aggregates and probabilities of improvement as CSV
rows, and ``report.md``, the tables a reader sees, with the figures
(``report_figures``)."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from datetime import date
from pathlib import Path
from typing import Any

import numpy as np

from ilfo.experiments import stats
from ilfo.experiments.report import STRONG_EXPERT, TABLE4_ALGOS, Cell, Report
from ilfo.experiments.report_figures import plot_curves, plot_profiles, profile_lines
from ilfo.paper import paper_ablation

Row = dict[str, Any]
"""A table row: column name -> value (text, a number, or None for none)."""


def _fmt(value: float | None, digits: int = 2) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _seeds_text(cell: Cell) -> str:
    unfinished = [r for r in cell.runs if not r.finished]
    text = str(len(cell.runs))
    if unfinished:
        least = min(r.final_step for r in unfinished)
        text += f" ({len(unfinished)} unfinished, from step {least:,})"
    return text


def aggregate_rows(report: Report) -> list[Row]:
    """Per algo x demos x variant: the IQM of all its tasks' runs, the mean and the median of
    its tasks' mean runs, each with a 95% stratified-bootstrap interval."""
    rows = []
    for algo, num_demos, variant in report.groups():
        envs = report.envs_of(algo, num_demos, variant)
        scores = report.task_scores(algo, num_demos, variant, envs)
        row: Row = {
            "algo": algo,
            "num_demos": num_demos,
            "variant": variant or "",
            "tasks": len(envs),
            "runs": int(np.isfinite(scores).sum()),
        }
        for name, aggregate in (("iqm", stats.iqm), ("mean", stats.mean), ("median", stats.median)):
            interval = stats.stratified_bootstrap(
                scores, aggregate, resamples=report.resamples, seed=0
            )
            row[name], row[f"{name}_low"], row[f"{name}_high"] = (
                interval.value,
                interval.low,
                interval.high,
            )
        rows.append(row)
    return rows


def improvement_rows(report: Report) -> list[Row]:
    """P(X > Y) for each pair of algos (no variant) with the same demos, on their shared
    tasks, with a 95% stratified-bootstrap interval."""
    rows = []
    groups = [g for g in report.groups() if g[2] is None]
    for x_algo, demos, _ in groups:
        for y_algo, y_demos, _ in groups:
            if y_demos != demos or y_algo == x_algo:
                continue
            shared = [
                e
                for e in report.envs_of(x_algo, demos, None)
                if e in report.envs_of(y_algo, demos, None)
            ]
            if not shared:
                continue
            interval = stats.probability_of_improvement_interval(
                report.task_scores(x_algo, demos, None, shared),
                report.task_scores(y_algo, demos, None, shared),
                resamples=report.resamples,
            )
            rows.append(
                {
                    "x": x_algo,
                    "y": y_algo,
                    "num_demos": demos,
                    "tasks": len(shared),
                    "p": interval.value,
                    "p_low": interval.low,
                    "p_high": interval.high,
                }
            )
    return rows


def _spread_text(cell: Cell) -> str:
    """The mean +- std and IQM [CI] columns; one seed has neither a spread nor an interval,
    so its cell shows its score alone ("0.94 ± 0.00" and "[0.94, 0.94]" would claim one)."""
    if len(cell.runs) == 1:
        return f"{_fmt(cell.mean)} | - (1 seed)"
    return f"{_fmt(cell.mean)} ± {_fmt(cell.std)} | {cell.iqm}"


def _versus_paper_text(cell: Cell) -> str:
    verdict = cell.versus_paper
    fraction = cell.expert_fraction
    if verdict and fraction is not None and fraction < STRONG_EXPERT:
        verdict += f" (expert at {fraction:.0%} of the paper's)"
    if cell.versus_paper in ("within", "above", "below") and len(cell.runs) == 1:
        verdict += " (1 seed: a single draw)"
    return verdict


def cell_rows(report: Report) -> list[Row]:
    """One row per cell: ilfo's statistics beside the paper's number."""
    rows = []
    for c in report.cells:
        rows.append(
            {
                "env": c.env,
                "algo": c.algo,
                "num_demos": c.num_demos,
                "variant": c.variant or "",
                "seeds": len(c.runs),
                "finished": c.finished,
                "final_step_min": min(r.final_step for r in c.runs),
                "mean": c.mean,
                "std": c.std,
                "iqm": c.iqm.value,
                "iqm_low": c.iqm.low,
                "iqm_high": c.iqm.high,
                "return_norm_mean": float(np.nanmean([r.final_return for r in c.runs]))
                if any(math.isfinite(r.final_return) for r in c.runs)
                else math.nan,
                "percent_difference": report.percent_difference(c),
                "paper_mean": None if c.paper is None else c.paper.mean,
                "paper_std": None if c.paper is None else c.paper.std,
                "paper_source": "" if c.paper is None else c.paper.where,
                "versus_paper": c.versus_paper,
                "expert_fraction_of_paper": c.expert_fraction,
                "seeds_list": " ".join(str(r.seed) for r in c.runs),
                "settings": c.settings_text,
            }
        )
    return rows


def write_report(report: Report, out: str | Path, *, sources: Sequence[str] = ()) -> list[Path]:
    """Write ``report.md``, ``cells.csv``, ``aggregates.csv``, ``improvement.csv`` and the
    figures (``curves_<env>.png``, ``profile_<demos>demos.png``) to ``out``; returns them."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cells, aggregates, improvements = (
        cell_rows(report),
        aggregate_rows(report),
        improvement_rows(report),
    )
    written = [
        _write_csv(out / f"{name}.csv", rows)
        for name, rows in (
            ("cells", cells),
            ("aggregates", aggregates),
            ("improvement", improvements),
        )
    ]
    figures = plot_curves(report, out) + plot_profiles(report, out)
    lines = _header_lines(report, sources) + _final_performance_lines(report, cells)
    lines += _variant_lines(report) + _aggregate_lines(aggregates)
    lines += _improvement_lines(improvements)
    if report.skipped:
        lines += ["", "## Left out", ""] + [f"- {s}" for s in report.skipped]
    if figures:
        lines += ["", "## Figures", "", *profile_lines(report), ""]
        lines += [f"![{p.stem}]({p.name})" for p in figures]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [path, *written, *figures]


def _write_csv(path: Path, rows: list[Row]) -> Path:
    with path.open("w", newline="") as f:
        if rows:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return path


def _header_lines(report: Report, sources: Sequence[str]) -> list[str]:
    return [
        "# ilfo report",
        "",
        f"{sum(len(c.runs) for c in report.cells)} runs in {len(report.cells)} cells"
        + (f", from {', '.join(sources)}" if sources else "")
        + f"; written {date.today().isoformat()}. Final performance = the last evaluation's "
        "fixed-horizon score normalised by the demos' mean return (the paper's); mean +- std "
        f"over seeds (population std); IQM with a 95% stratified-bootstrap interval "
        f"({report.resamples} resamples, percentile). `vs paper`: within, above or below the "
        "paper's mean +- 2 std (Tables 1-2), with the expert's strength where its demos "
        f"return less than {STRONG_EXPERT:.0%} of the paper's expert (easier demos to match: "
        "the scores flatter ilfo). `settings`: where the runs were trained otherwise "
        "than `ilfo train`'s defaults (the paper's protocol).",
    ]


def _final_performance_lines(report: Report, cells: list[Row]) -> list[str]:
    lines = [
        "",
        "## Final performance",
        "",
        "| task | algo | demos | variant | seeds | mean ± std | IQM [95% CI] | return (norm.) "
        "| paper | vs paper | settings |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c, row in zip(report.cells, cells, strict=True):
        paper = "" if c.paper is None or c.variant else c.paper.text
        lines.append(
            f"| {c.env} | {c.algo} | {c.num_demos} | {c.variant or ''} | {_seeds_text(c)} | "
            f"{_spread_text(c)} | {_fmt(row['return_norm_mean'])} | "
            f"{paper} | {_versus_paper_text(c)} | {c.settings_text} |"
        )
    return lines


def _variant_lines(report: Report) -> list[str]:
    variants = [
        (c, report.percent_difference(c))
        for c in report.cells
        if c.variant or (c.algo in TABLE4_ALGOS and report.percent_difference(c) is not None)
    ]
    if not variants:
        return []
    lines = [
        "",
        "## Variants (percent difference of the mean from the default run, as Table 4)",
        "",
        "Seeds: this cell's; the default's (an unfinished run counts with its last "
        "evaluation so far).",
        "",
        "| task | algo | demos | variant | seeds | ilfo % | paper % (10 demos) "
        "| trained otherwise |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c, diff in variants:
        variant = c.variant or TABLE4_ALGOS[c.algo]
        paper_cell = c.paper if c.variant else paper_ablation(c.env, variant)
        paper = "" if paper_cell is None else paper_cell.text
        base = report.base_cell(c)
        otherwise = (
            ""
            if base is None or base.settings_text == c.settings_text
            else f"this: {c.settings_text or 'defaults'}; "
            f"{base.algo}: {base.settings_text or 'defaults'}"
        )
        seeds = _seeds_text(c) + ("" if base is None else f"; {_seeds_text(base)}")
        lines.append(
            f"| {c.env} | {c.algo} | {c.num_demos} | {variant} | {seeds} | {_fmt(diff, 1)} "
            f"| {paper} | {otherwise} |"
        )
    return lines


def _aggregate_lines(aggregates: list[Row]) -> list[str]:
    lines = [
        "",
        "## Aggregates over tasks",
        "",
        "| algo | demos | variant | tasks | runs | IQM [95% CI] | mean of tasks [95% CI] "
        "| median of tasks [95% CI] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in aggregates:
        cis = " | ".join(
            f"{_fmt(r[k])} [{_fmt(r[f'{k}_low'])}, {_fmt(r[f'{k}_high'])}]"
            for k in ("iqm", "mean", "median")
        )
        lines.append(
            f"| {r['algo']} | {r['num_demos']} | {r['variant']} | {r['tasks']} | {r['runs']} "
            f"| {cis} |"
        )
    return lines


def _improvement_lines(improvements: list[Row]) -> list[str]:
    if not improvements:
        return []
    lines = [
        "",
        "## Probability of improvement",
        "",
        "| X | Y | demos | tasks | P(X > Y) [95% CI] |",
        "|---|---|---|---|---|",
    ]
    for r in improvements:
        lines.append(
            f"| {r['x']} | {r['y']} | {r['num_demos']} | {r['tasks']} | "
            f"{_fmt(r['p'])} [{_fmt(r['p_low'])}, {_fmt(r['p_high'])}] |"
        )
    return lines
