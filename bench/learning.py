"""Learning benchmark: OOPS+TD3 on Hopper-v5 from 1 demo, several seeds, normalised return vs steps.

Each seed is a normal `ilfo train` run in a fixed directory,
bench_runs/learning/<env>__<algo>__<seed>, so the benchmark is resumable: run it again (with the
same or a larger --steps) and every seed continues from its last checkpoint.
Target (issue): >= 0.8 normalised return by 300k steps; the paper reaches 0.98 by 1M.

    python bench/learning.py --steps 300000 --seeds 0 1 2          # hours on 2 cores
    python bench/learning.py --steps 300000 --seeds 0 1 2 --json   # one JSON line per eval

The score is the paper's: deterministic fixed-horizon evaluation, divided by the demos' mean
return (eval_score_norm); the standard return (stop at the first fall) is reported beside it.
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import date
from pathlib import Path

import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.benchmarking import machine
from ilfo.training import TrainConfig, Trainer, plot_runs, read_metrics


def run_seed(config: TrainConfig, run_dir: Path) -> Path:
    if (run_dir / "config.json").is_file():  # resume finds the newest checkpoint, if any
        trainer = Trainer.resume(run_dir, steps=config.steps)
    else:
        trainer = Trainer(config, run_dir)
    if trainer.step < config.steps:
        trainer.train()
    return run_dir


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--env", default="Hopper-v5")
    parser.add_argument("--algo", default="oops-td3")
    parser.add_argument("--steps", type=int, default=300_000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--preset", default="paper", choices=["paper", "fast"])
    parser.add_argument("--demos", default=None, help="demo file (default: the shipped expert)")
    parser.add_argument("--out", default="bench_runs/learning")
    parser.add_argument(
        "--updates-per-step", type=int, default=1, help="update-to-data ratio (paper: 1)"
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    run_dirs = []
    for seed in args.seeds:
        config = TrainConfig(
            env=args.env,
            algo=args.algo,
            steps=args.steps,
            seed=seed,
            preset=args.preset,
            demos=args.demos,
            num_demos=1,
            out=args.out,
            updates_per_step=args.updates_per_step,
        )
        run_dirs.append(run_seed(config, Path(args.out) / f"{args.env}__{args.algo}__{seed}"))

    meta = {
        "date": date.today().isoformat(),
        "machine": machine(),
        "env": args.env,
        "algo": args.algo,
        "preset": args.preset,
        "updates_per_step": args.updates_per_step,
        "contact_forces": config.observes_contact_forces,
    }
    curves = {}
    for seed, run_dir in zip(args.seeds, run_dirs, strict=True):
        rows = [r for r in read_metrics(run_dir) if r["eval_score"]]
        curves[seed] = rows
        if args.json:
            for r in rows:
                print(
                    json.dumps(
                        {
                            "bench": "learning",
                            **meta,
                            "seed": seed,
                            "step": int(r["step"]),
                            "score_norm": float(r["eval_score_norm"]),
                            "return_norm": float(r["eval_return_norm"]),
                            "ot_distance": float(r["eval_ot_distance"]),
                        }
                    )
                )
    final = [float(rows[-1]["eval_score_norm"]) for rows in curves.values() if rows]
    best = [max(float(r["eval_score_norm"]) for r in rows) for rows in curves.values() if rows]
    plot_runs(run_dirs, Path(args.out) / "learning_curves.png")
    summary = {
        "bench": "learning_summary",
        **meta,
        "steps": args.steps,
        "seeds": args.seeds,
        "final_score_norm_mean": float(np.mean(final)) if final else None,
        "final_score_norm_std": float(np.std(final)) if final else None,
        "best_score_norm_mean": float(np.mean(best)) if best else None,
    }
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
