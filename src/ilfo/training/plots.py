"""Learning curves of runs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ilfo.training.metrics import read_metrics


def plot_runs(run_dirs: list[Path], out: Path, metric: str | None = None) -> Path:
    """Evaluation curves of runs, grouped by env and algo: mean over seeds with min-max band.

    ``metric`` defaults to the normalised score where demos gave a return, else the raw score.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    chosen = metric
    for run_dir in run_dirs:
        cfg = json.loads((Path(run_dir) / "config.json").read_text())
        rows = [r for r in read_metrics(run_dir) if r.get("eval_score")]
        if not rows:
            continue
        name = chosen or ("eval_score_norm" if rows[0].get("eval_score_norm") else "eval_score")
        chosen = name
        steps = np.array([float(r["step"]) for r in rows])
        values = np.array([float(r[name]) for r in rows])
        groups.setdefault(f"{cfg['env']} {cfg['algo']}", []).append((steps, values))
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
    ax.set_ylabel(chosen or "eval_score")
    ax.grid(alpha=0.3)
    if groups:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
