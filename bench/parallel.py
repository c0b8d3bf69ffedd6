"""Sweep throughput: two one-core runs at once against the same runs one after another on two cores.

On a 2-core machine a sweep can give each run both cores (``--cores-per-run 2``, one run at a
time) or one core each (``--cores-per-run 1``, two at once). Which finishes a matrix of runs
sooner depends on how well one run's jitted updates use a second thread. This runs the same two
short OOPS+TD3 runs (Hopper-v5, the shipped expert's first demo, fast preset) both ways through
the local sweep backend and reports each run's training rate after its random-action warm-up
(the mean of ``steps_per_s`` in its ``metrics.csv`` past ``start_steps``) and the runs' combined
rate (training steps of all runs / the span from the first start to the last end).

    python bench/parallel.py                      # 2 runs of 25,000 steps, ~6 min
    python bench/parallel.py --steps 15000 --json
"""

from __future__ import annotations

import argparse
import csv
import shutil
import sys
import tempfile
from pathlib import Path

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.benchmarking import print_rows
from ilfo.experiments import LocalBackend, SweepSpec, create_sweep, read_attempts, run_sweep

START_STEPS = 5000


def run_rate(metrics: Path, start_steps: int) -> float:
    """Mean logged steps/s of the episodes that end after the warm-up (the training phase)."""
    with metrics.open() as f:
        rates = [
            float(row["steps_per_s"])
            for row in csv.DictReader(f)
            if row["steps_per_s"] and int(row["step"]) > start_steps
        ]
    if not rates:
        raise RuntimeError(f"{metrics}: no training episodes logged")
    return sum(rates) / len(rates)


def measure(mode: str, steps: int, root: Path) -> dict[str, float | str | int]:
    cores_per_run, workers = (1, 2) if mode == "parallel" else (2, 1)
    config = {
        "steps": steps,
        "start_steps": START_STEPS,
        "eval_every": steps,
        "eval_episodes": 1,
        "checkpoint_every": steps,
        "preset": "fast",
        "replay_capacity": steps,
    }
    spec = SweepSpec(env=("Hopper-v5",), algo=("oops-td3",), seed=(0, 1), config=config)
    sweep = create_sweep(root, spec)
    final = run_sweep(sweep, LocalBackend(cores_per_run, workers), poll_seconds=0.5)
    if any(s.state != "done" for s in final):
        raise RuntimeError(f"{mode}: runs did not finish: {final}")
    rates = [
        run_rate(next(sweep.run_dir(run.name).rglob("metrics.csv")), START_STEPS)
        for run in sweep.runs
    ]
    events = [read_attempts(sweep, run.name) for run in sweep.runs]
    span = max(e[-1]["time"] for e in events) - min(e[0]["time"] for e in events)
    return {
        "mode": mode,
        "cores_per_run": cores_per_run,
        "at_once": workers,
        "steps": steps,
        "run_steps_per_s": sum(rates) / len(rates),
        "span_s": span,
        "combined_steps_per_s": len(sweep.runs) * steps / span,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=25000, help="steps of each run")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.steps <= START_STEPS:
        parser.error(f"--steps must exceed the warm-up of {START_STEPS} steps")
    rows = []
    for mode in ("sequential", "parallel"):
        root = Path(tempfile.mkdtemp(prefix=f"ilfo-bench-parallel-{mode}-"))
        try:
            rows.append(measure(mode, args.steps, root))
        finally:
            shutil.rmtree(root, ignore_errors=True)
    columns = {
        "mode": "{mode}",
        "cores per run": "{cores_per_run}",
        "runs at once": "{at_once}",
        "training steps/s per run": "{run_steps_per_s:.0f}",
        "span s": "{span_s:.0f}",
        "all runs steps/s": "{combined_steps_per_s:.0f}",
    }
    print_rows(rows, columns, args.json)


if __name__ == "__main__":
    main()
