"""Benchmark: the steps per second of one core that ilfo's estimates use, from the kept runs.

Every run directory under ``docs/results/{runs,probes,controls}`` with a ``config.json`` and a
``metrics.csv`` of at least ``--min-steps`` steps gives one rate: its last row's step over its
wall time (the loop's own clock: evaluations and checkpoints included, the time between a stop
and a resume not). Those runs were each pinned to one core beside another run on the project's
2-core machines, which is how sweeps run, so the rates are what a sweep's run gets.

Rates are grouped by algo, and within it by env; the median of each group is written to
``src/ilfo/experiments/rates.json`` (with the date, this machine and the commit), which
``ilfo.experiments.estimates`` reads for ``ilfo train``'s start summary and ``ilfo reproduce``'s
plans. Only runs at one update per step, and at the fast preset where the preset changes the
algo's agent (the estimate costs the paper preset from the fast rate), count.

    python bench/rates.py            # print the table, write rates.json
    python bench/rates.py --check    # print only; exit 1 if rates.json differs
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import subprocess
import sys
from collections import defaultdict
from datetime import date
from pathlib import Path

sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.benchmarking import machine
from ilfo.experiments.estimates import preset_changes_agent_of

ROOT = Path(__file__).resolve().parent.parent
RATES_FILE = ROOT / "src" / "ilfo" / "experiments" / "rates.json"
KEPT = ("runs", "probes", "controls")


def run_rate(run_dir: Path, min_steps: int) -> tuple[dict, float] | None:
    """(config, steps per second) of a kept run, or None where it does not count."""
    try:
        config = json.loads((run_dir / "config.json").read_text())
        with open(run_dir / "metrics.csv", newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, ValueError):
        return None
    if not rows or int(rows[-1]["step"]) < min_steps or float(rows[-1]["wall_time"]) <= 0:
        return None
    if config.get("updates_per_step", 1) != 1:
        return None
    if config.get("preset") != "fast" and preset_changes_agent_of(config["algo"]):
        return None
    return config, int(rows[-1]["step"]) / float(rows[-1]["wall_time"])


def measure(results: Path, min_steps: int) -> dict[str, dict]:
    """Per algo: the median rate, its runs, and the median per env."""
    by_algo: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for kind in KEPT:
        for run_dir in sorted((results / kind).iterdir()):
            found = run_rate(run_dir, min_steps)
            if found is not None:
                config, rate = found
                by_algo[config["algo"]][config["env"]].append(rate)
    table = {}
    for algo, envs in sorted(by_algo.items()):
        every = [rate for rates in envs.values() for rate in rates]
        table[algo] = {
            "steps_per_s": round(statistics.median(every), 1),
            "runs": len(every),
            "envs": {env: round(statistics.median(r), 1) for env, r in sorted(envs.items())},
        }
    return table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, default=ROOT / "docs" / "results")
    parser.add_argument("--min-steps", type=int, default=50_000)
    parser.add_argument("--check", action="store_true", help="compare with rates.json only")
    args = parser.parse_args()
    table = measure(args.results, args.min_steps)
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    print(f"{date.today().isoformat()}, {machine()}, commit {commit}")
    print("| algo | kept runs | median steps/s | per env (median) |")
    print("|---|---|---|---|")
    for algo, row in table.items():
        envs = ", ".join(f"{env} {rate:.0f}" for env, rate in row["envs"].items())
        print(f"| {algo} | {row['runs']} | {row['steps_per_s']:.0f} | {envs} |")
    if args.check:
        written = json.loads(RATES_FILE.read_text())["algos"]
        return 0 if written == table else 1
    record = {
        "date": date.today().isoformat(),
        "machine": machine(),
        "commit": commit,
        "source": "bench/rates.py over docs/results/{runs,probes,controls}",
        "algos": table,
    }
    RATES_FILE.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {RATES_FILE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
