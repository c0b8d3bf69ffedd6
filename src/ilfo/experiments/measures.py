"""What ``ilfo reproduce`` measures of finished runs' final rollouts and keeps in each run
(table3's Wasserstein distances, the solver figure's couplings): computed once per final
policy, pair by pair, so that a measurement stopped partway continues where it stood."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ilfo.experiments.distances import PairMeasure


def cached_measure(
    run: Any,
    name: str,
    episodes: int,
    compute: Any,
    log: Callable[[str], None] | None = None,
) -> dict[str, float]:
    """``compute()``'s values for a run, kept in its directory as ``name``: computed again only
    where the run trained on since (its last step) or other ``episodes`` are asked for.
    ``log`` gets a line before and after a computation (not for a value kept from before)."""
    import time

    from ilfo.files import write_json_atomic

    cache = run.run_dir / name
    key = _cache_key(run, episodes)
    kept = read_kept(cache, "values")
    if kept is not None and kept[0] == key:
        return kept[1]
    if log is not None:
        log(
            f"{run.run_dir.name}: measuring {Path(name).stem}, {episodes} final rollouts against "
            f"{episodes} expert trajectories ..."
        )
    start = time.monotonic()
    values = compute()
    write_json_atomic(cache, {"key": key, "values": values})
    if log is not None:
        log(f"{run.run_dir.name}: {Path(name).stem} measured in {time.monotonic() - start:.0f} s")
    return values


def read_kept(path: Path, part: str) -> tuple[Any, dict[str, Any]] | None:
    """A kept measure's key and its ``part`` (``values`` of a finished one, ``pairs`` of a
    partial one); None where there is none or it is damaged (a power loss, a hand edit):
    measured again rather than a crash at every start."""
    import json

    try:
        kept = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(kept, dict) or not isinstance(kept.get(part), dict):
        return None
    return kept.get("key"), kept[part]


def _cache_key(run: Any, episodes: int) -> dict[str, int]:
    """What a run's cached measure was measured on: its final policy's step, and the episodes."""
    return {"trained_step": run.trained_step, "episodes": episodes}


PROGRESS_LOG_SECONDS = 60.0
"""A pair-by-pair measurement says how far it is at most this often."""


def measure_pairs(
    run: Any,
    name: str,
    episodes: int,
    measure: PairMeasure,
    log: Callable[[str], None] | None = None,
) -> dict[str, float]:
    """``measure(rollout, expert)`` averaged over the pairs of a run's final rollouts and its
    first expert trajectories (``distances.mean_over_pairs``), cached as ``name`` (see
    ``cached_measure``). Each pair is kept in ``run_dir.partial_measure_file(name)`` as it is
    measured (a run's snapshot keeps it, and the finished measure), so an
    interrupted measurement (hours, for the solver figure at the full budget) continues where
    it stopped: on the same rollouts, to the last bit, or from the start."""
    import time

    from ilfo.experiments.distances import final_rollouts, mean_over_pairs, trajectories_digest
    from ilfo.files import write_json_atomic
    from ilfo.training.run_dir import partial_measure_file

    partial = run.run_dir / partial_measure_file(name)

    def compute() -> dict[str, float]:
        rollouts, experts = final_rollouts(run.run_dir, episodes=episodes, experts=episodes)
        # Pairs are kept for these very rollouts: a measurement continued on another machine,
        # whose floats roll the same policy out a little differently, starts again.
        key = {**_cache_key(run, episodes), "trajectories": trajectories_digest(rollouts + experts)}
        kept = read_kept(partial, "pairs")  # None where there is none, or it is damaged
        done: dict[str, dict[str, float]] = dict(kept[1]) if kept and kept[0] == key else {}
        total, start, last_log = len(rollouts) * len(experts), time.monotonic(), time.monotonic()
        if log is not None and done:
            log(f"{run.run_dir.name}: {len(done)} of {total} pairs kept from before")
        elif log is not None and kept and kept[1]:
            log(
                f"{run.run_dir.name}: the {len(kept[1])} pairs kept from before are of another "
                "final policy or other rollouts of it (another machine's floats): measuring again"
            )

        def keep(pair: str, values: dict[str, float]) -> None:
            nonlocal last_log
            done[pair] = values
            write_json_atomic(partial, {"key": key, "pairs": done})
            if log is not None and time.monotonic() - last_log >= PROGRESS_LOG_SECONDS:
                minutes = (time.monotonic() - start) / 60
                log(f"{run.run_dir.name}: {len(done)} of {total} pairs ({minutes:.0f} min)")
                last_log = time.monotonic()

        return mean_over_pairs(rollouts, experts, measure, done=done, on_pair=keep)

    values = cached_measure(run, name, episodes, compute, log)
    partial.unlink(missing_ok=True)  # only once the finished measure is kept
    return values


def _finished(runs: list[Any]) -> tuple[list[Any], list[str]]:
    """The runs trained to their budgets (their final policies are what is measured), and the
    names of the others, left out."""
    done = [r for r in runs if r.finished]
    return done, [r.run_dir.name for r in runs if not r.finished]


def _left_out_line(names: list[str]) -> list[str]:
    if not names:
        return []
    return ["", f"Not measured, unfinished: {', '.join(names)}."]


def write_distances(
    runs: list[Any], out: Path, episodes: int = 10, log: Callable[[str], None] | None = None
) -> list[Path]:
    """Table 3: each run's distances (cached in its directory as distances.json), their mean
    per task x algo x demos beside the paper's, as ``distances.csv`` and ``distances.md``.
    ``log``: see ``cached_measure``."""

    import numpy as np

    from ilfo.experiments.distances import SPACES, pair_distances
    from ilfo.paper import paper_cells
    from ilfo.training.run_dir import DISTANCES_FILE

    runs, unfinished = _finished(runs)
    per_cell: dict[tuple[str, str, int], list[dict[str, float]]] = {}
    for run in runs:
        values = measure_pairs(run, DISTANCES_FILE, episodes, pair_distances, log)
        per_cell.setdefault((run.env, run.algo, run.num_demos), []).append(values)
    paper = {(c.env, c.algo, c.space): c for c in paper_cells() if c.table == "table3"}
    rows = []
    for (env, algo, demos), cell_values in per_cell.items():
        row: dict[str, Any] = {
            "env": env,
            "algo": algo,
            "num_demos": demos,
            "seeds": len(cell_values),
        }
        for space in SPACES:
            row[space] = float(np.mean([v[space] for v in cell_values]))
            cell = paper.get((env, algo, space))
            row[f"paper {space}"] = None if cell is None else cell.mean
        rows.append(row)
    csv_path = out / "distances.csv"
    _write_rows(csv_path, rows)
    lines = [
        "# Wasserstein distances of final rollouts to the expert (Table 3)",
        "",
        f"{episodes} deterministic fixed-horizon rollouts of each run's final policy against the "
        f"first {episodes} expert trajectories of its demo file; exact W1 (network simplex) with "
        "the Euclidean cost between raw atoms, the mean over all pairs, then over seeds. "
        "ilfo's (the paper's).",
        "",
        "| task | algo | demos | seeds | (s) | (s, s') | (s, a) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        cells = " | ".join(
            f"{row[s]:.2f}" + ("" if row[f"paper {s}"] is None else f" ({row[f'paper {s}']:.2f})")
            for s in SPACES
        )
        lines.append(
            f"| {row['env']} | {row['algo']} | {row['num_demos']} | {row['seeds']} | {cells} |"
        )
    lines += _left_out_line(unfinished)
    md_path = out / "distances.md"
    md_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [md_path, csv_path]


def write_solvers(
    runs: list[Any], out: Path, episodes: int = 10, log: Callable[[str], None] | None = None
) -> list[Path]:
    """The solver figure: per run, the (s, s') transport costs of its final rollouts under each
    coupling (cached in the run as solvers.json), as ``solvers.md``, ``solvers.csv`` and
    ``solvers_<env>_<seed>.png``. ``log``: see ``cached_measure``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ilfo.experiments.distances import SOLVER_LAMBDAS, solver_costs
    from ilfo.experiments.report_figures import finish_figure
    from ilfo.training.run_dir import SOLVERS_FILE

    runs, unfinished = _finished(runs)
    rows = []
    for run in runs:
        values = measure_pairs(run, SOLVERS_FILE, episodes, solver_costs, log)
        rows.append({"env": run.env, "algo": run.algo, "seed": run.seed, **values})
    csv_path = out / "solvers.csv"
    _write_rows(csv_path, rows)
    lines = [
        "# Solvers: the (s, s') transport cost of final rollouts under each coupling",
        "",
        f"OOPS+TD3's final policy: {episodes} rollouts against the first {episodes} expert "
        "trajectories; the cost <C, P> (Euclidean C between raw atoms) of the exact coupling "
        "(simplex), PWIL's greedy one and Sinkhorn's at each lambda (with the share of its "
        "solves that converged where not all did). Every coupling bounds the exact distance "
        "from above: lower is tighter.",
        "",
        "| task | seed | W_simplex | W_greedy | "
        + " | ".join(f"W_Sk({lam:g})" for lam in SOLVER_LAMBDAS)
        + " |",
        "|---|---|---|---|" + "---|" * len(SOLVER_LAMBDAS),
    ]
    md_path = out / "solvers.md"
    written = [md_path, csv_path]
    for row in rows:
        sk = []
        for lam in SOLVER_LAMBDAS:
            share = row[f"converged({lam:g})"]
            note = "" if share == 1 else f" ({share:.0%} converged)"
            sk.append(f"{row[f'W_Sk({lam:g})']:.3f}{note}")
        lines.append(
            f"| {row['env']} | {row['seed']} | {row['W_simplex']:.3f} | {row['W_greedy']:.3f} "
            f"| {' | '.join(sk)} |"
        )
        fig, ax = plt.subplots(figsize=(5, 3.5))
        sinkhorn = [row[f"W_Sk({lam:g})"] for lam in SOLVER_LAMBDAS]
        ax.plot(SOLVER_LAMBDAS, sinkhorn, "o-", label="W_Sk(lambda)")
        ax.axhline(row["W_simplex"], color="orange", label="W_simplex")
        ax.axhline(row["W_greedy"], color="red", label="W_greedy")
        ax.set_xscale("log")
        title = f"{row['env']} (seed {row['seed']})"
        path = out / f"solvers_{row['env']}_{row['seed']}.png"
        written.append(
            finish_figure(fig, ax, title, "Sinkhorn lambda", "transport cost <C, P>", path)
        )
    lines += _left_out_line(unfinished)
    md_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return written


def _write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    import csv

    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["env"])
        writer.writeheader()
        writer.writerows(rows)
