"""Sweep backends: the overhead of Ray against the local process pool on the same tiny sweep.

The same sweep (oops-td3 and pwil-td3 on Hopper-v5 from the bundled scripted demos, 2 seeds,
100-step episodes, 600 steps each: 4 runs) runs through each backend from scratch, one run per
core; the table gives the sweep's wall time, the runs' own time (each worker's start to end, as
its attempts record them) and what the backend adds around them (start-up, scheduling,
shut-down).

    python bench/sweep.py                 # both backends (Ray needs pip install -e ".[ray]")
    python bench/sweep.py --backends local --json
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.benchmarking import print_rows
from ilfo.experiments import (
    LocalBackend,
    RayBackend,
    SweepSpec,
    create_sweep,
    read_attempts,
    run_sweep,
)
from ilfo.paths import bundled_demos

CONFIG = {
    "demos": str(bundled_demos("Hopper-v5-scripted")),
    "horizon": 100,
    "start_steps": 200,
    "steps": 600,
    "eval_every": 200,
    "eval_episodes": 1,
    "checkpoint_every": 200,
    "preset": "fast",
    "replay_capacity": 5000,
}


def measure(backend_name: str, root: Path) -> dict[str, float | str]:
    spec = SweepSpec(algo=("oops-td3", "pwil-td3"), seed=(0, 1), config=CONFIG)
    sweep = create_sweep(root, spec)
    start = time.perf_counter()
    backend = LocalBackend(1) if backend_name == "local" else RayBackend(cores_per_run=1)
    ready = time.perf_counter()
    final = run_sweep(sweep, backend, poll_seconds=0.2)
    wall = time.perf_counter() - start
    if any(s.state != "done" for s in final):
        raise RuntimeError(f"{backend_name}: runs did not finish: {final}")
    spans = []
    for run in sweep.runs:
        events = read_attempts(sweep, run.name)
        spans.append(events[-1]["time"] - events[0]["time"])
    first_start = min(read_attempts(sweep, r.name)[0]["time"] for r in sweep.runs)
    last_end = max(read_attempts(sweep, r.name)[-1]["time"] for r in sweep.runs)
    return {
        "backend": backend_name,
        "runs": len(sweep.runs),
        "slots": backend.slots,
        "wall_s": wall,
        "backend_start_s": ready - start,
        "run_s_mean": sum(spans) / len(spans),
        "runs_span_s": last_end - first_start,
        "overhead_s": wall - (last_end - first_start),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--backends", nargs="+", default=["local", "ray"], choices=["local", "ray"])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = []
    for name in args.backends:
        root = Path(tempfile.mkdtemp(prefix=f"ilfo-bench-sweep-{name}-"))
        try:
            rows.append(measure(name, root))
        finally:
            shutil.rmtree(root, ignore_errors=True)
    columns = {
        "backend": "{backend}",
        "runs": "{runs}",
        "at once": "{slots}",
        "sweep wall s": "{wall_s:.1f}",
        "backend start s": "{backend_start_s:.1f}",
        "run s (mean)": "{run_s_mean:.1f}",
        "first start to last end s": "{runs_span_s:.1f}",
        "overhead s": "{overhead_s:.1f}",
    }
    print_rows(rows, columns, args.json)


if __name__ == "__main__":
    main()
