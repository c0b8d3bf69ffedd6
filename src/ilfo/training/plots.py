"""Learning curves of runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ilfo.training.metrics import read_metrics
from ilfo.training.migrations import read_run_config
from ilfo.training.run_dir import CONFIG_FILE

Curve = tuple[np.ndarray, np.ndarray]
"""A run's steps and values of the plotted metric."""


def plot_runs(run_dirs: list[Path], out: Path, metric: str | None = None) -> Path:
    """Curves of runs, one per ``curve_groups`` group: mean over seeds with min-max band.

    ``metric`` is a metrics.csv column, plotted over the rows that log it; by default the
    normalised evaluation score where demos gave a return, else the raw one. Raises ValueError
    for a column the runs do not log, a value that is not a number (naming the file), or runs
    with no value to plot (no evaluation yet).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chosen, groups = curve_groups(run_dirs, metric)
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, curves in groups.items():
        length = min(len(s) for s, _ in curves)
        steps = curves[0][0][:length]
        values = np.stack([v[:length] for _, v in curves])
        mean = values.mean(axis=0)
        ax.plot(steps, mean, label=f"{label} ({len(curves)} seed{'s' * (len(curves) > 1)})")
        if len(curves) > 1:
            ax.fill_between(steps, values.min(axis=0), values.max(axis=0), alpha=0.25)
    ax.set_xlabel("environment steps")
    ax.set_ylabel(chosen)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def curve_groups(
    run_dirs: list[Path], metric: str | None = None
) -> tuple[str, dict[str, list[Curve]]]:
    """The metric plotted (``plot_runs``'s ``metric`` or its default) and the runs' curves by
    label, one label per env, algo, demos, variant and training settings (``run_labels``: what
    ``ilfo report`` sets its cells by and names): runs trained otherwise are not seeds of one
    curve. Where runs of one env, algo, demos and variant differ in their settings, each
    curve's label names its settings ("defaults" for none). Runs without a value yet are left
    out."""
    from ilfo.training.run_labels import run_variant, training_settings

    keyed: dict[tuple[str, tuple[str, ...]], list[Curve]] = {}
    chosen = metric
    for run_dir in run_dirs:
        cfg = read_run_config(run_dir)
        source = Path(run_dir) / CONFIG_FILE
        if not isinstance(cfg.get("env"), str) or not isinstance(cfg.get("algo"), str):
            raise ValueError(f"{source} names no env and algo")
        all_rows = read_metrics(run_dir)
        if metric is not None and all_rows and metric not in all_rows[0]:
            numeric = [k for k in all_rows[0] if k not in ("step", "episode")]
            raise ValueError(f"no metric {metric!r} in {run_dir}; choose one of {numeric}")
        rows = [r for r in all_rows if r.get(metric or "eval_score")]
        if not rows:
            continue
        chosen = chosen or ("eval_score_norm" if rows[0].get("eval_score_norm") else "eval_score")
        variant = run_variant(cfg, source)
        demos = int(cfg.get("num_demos", 1))
        task = f"{cfg['env']} {cfg['algo']}{f' [{variant}]' if variant else ''}"
        task += f", {demos} demo{'s' * (demos > 1)}"
        curve = (_column(rows, "step", run_dir), _column(rows, chosen, run_dir))
        keyed.setdefault((task, training_settings(cfg, source)), []).append(curve)
    if not keyed:
        where = ", ".join(map(str, run_dirs))
        raise ValueError(f"nothing to plot: no {metric or 'evaluation'} logged yet in {where}")
    tasks = [task for task, _ in keyed]
    groups = {
        task if tasks.count(task) == 1 else f"{task}, {'; '.join(settings) or 'defaults'}": curves
        for (task, settings), curves in keyed.items()
    }
    return chosen or "eval_score", groups


def _column(rows: list[dict[str, str]], name: str, run_dir: Path) -> np.ndarray:
    """Column ``name`` of metrics rows as floats; a ValueError names the file and the step."""
    try:
        return np.array([float(r[name]) for r in rows])
    except (TypeError, ValueError):
        bad = next(r for r in rows if not _is_float(r[name]))
        raise ValueError(
            f"{Path(run_dir) / 'metrics.csv'}: {name} {bad[name]!r} at step {bad.get('step')} "
            "is not a number (a damaged file?)"
        ) from None


def _is_float(text: str | None) -> bool:
    try:
        float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    return True
