"""The ``ilfo`` command line: thin wrappers over the library."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path

import numpy as np

from ilfo import demos
from ilfo.config import add_dataclass_arguments, overrides_from_args
from ilfo.paths import bundled_demos
from ilfo.rewards import OOPS, PWIL, OOPSConfig


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ilfo`` console script."""
    parser = argparse.ArgumentParser(
        prog="ilfo", description="Imitation learning from observation (OOPS and its peers)."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    _add_train_parser(sub)
    _add_eval_parser(sub)
    _add_plot_parser(sub)
    _add_reward_parser(sub)
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"ilfo: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


def _add_train_parser(sub: argparse._SubParsersAction) -> None:
    from ilfo.train import TrainConfig

    p = sub.add_parser(
        "train",
        help="Train a policy (default: OOPS+TD3 on Hopper-v5 from one shipped expert demo).",
        description=(
            "Train a policy from state-only demonstrations (or on the task reward for td3/sac). "
            "Writes runs/<env>__<algo>__<seed>__<time>/ with config.json, metrics.csv, "
            "checkpoints/, policy.msgpack and learning_curve.png. Ctrl-C checkpoints; "
            "--resume RUN_DIR continues exactly where the run stopped."
        ),
    )
    add_dataclass_arguments(p, TrainConfig)
    p.add_argument(
        "--resume",
        metavar="RUN_DIR",
        default=None,
        help="continue a run from its last checkpoint (--steps may extend it)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_train)


def _run_train(args: argparse.Namespace) -> int:
    from ilfo.train import TrainConfig, Trainer, run_name

    overrides = overrides_from_args(args, TrainConfig)
    if args.resume:
        extra = set(overrides) - {"steps"}
        if extra:
            raise ValueError(f"--resume takes its config from the run; drop {sorted(extra)}")
        trainer = Trainer.resume(
            args.resume, progress=not args.no_progress, steps=overrides.get("steps")
        )
    else:
        config = TrainConfig(**overrides)
        trainer = Trainer(
            config, Path(config.out) / run_name(config), progress=not args.no_progress
        )
    print(f"run directory: {trainer.run_dir}")
    run_dir = trainer.train()
    final = trainer.last_eval
    print(f"done: {run_dir}  last evaluation: {json.dumps(final)}")
    return 0


def _add_eval_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="Evaluate a run's policy (deterministic episodes).")
    p.add_argument("run_dir", help="a run directory written by `ilfo train`")
    p.add_argument("--episodes", type=int, default=10, help="episodes to run")
    p.add_argument(
        "--video",
        default=None,
        metavar="OUT.mp4",
        help="also record the first episode (needs MuJoCo offscreen rendering)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON line")
    p.set_defaults(run=_run_eval)


def _run_eval(args: argparse.Namespace) -> int:
    from ilfo.evaluate import evaluate_run

    result = evaluate_run(Path(args.run_dir), episodes=args.episodes, video=args.video)
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>20s}: {value}")
    return 0


def _add_plot_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plot", help="Plot evaluation curves of runs (mean and spread over seeds).")
    p.add_argument("run_dirs", nargs="+", help="run directories")
    p.add_argument("--out", default="learning_curves.png", help="output image")
    p.add_argument(
        "--metric",
        default=None,
        help="a metrics.csv column (default: eval_score_norm, else eval_score)",
    )
    p.set_defaults(run=_run_plot)


def _run_plot(args: argparse.Namespace) -> int:
    from ilfo.train import plot_runs

    dirs = [Path(d) for d in args.run_dirs]
    for d in dirs:
        if not (d / "metrics.csv").is_file() or not (d / "config.json").is_file():
            raise FileNotFoundError(f"{d} is not a run directory (no metrics.csv/config.json)")
    out = plot_runs(dirs, Path(args.out), args.metric)
    print(f"wrote {out}")
    return 0


def _add_reward_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reward",
        help="Score learner episodes against expert demos with the OOPS (or PWIL) reward.",
        description=(
            "Compute per-step OT rewards of learner episodes against a demonstration and print "
            "one line per episode. By default: the bundled Hopper-v5 scripted rollouts, demo 0 "
            "as the expert, and as learners another episode of the same policy, that demo plus "
            "noise, and a random-action episode."
        ),
    )
    p.add_argument("--demos", default=None, help="demo .npz file (default: bundled Hopper-v5)")
    p.add_argument("--expert", type=int, default=0, help="index of the expert episode")
    p.add_argument(
        "--learners", type=int, nargs="*", default=None, help="indices of learner episodes"
    )
    p.add_argument("--rewarder", choices=["oops", "pwil"], default="oops")
    docs = {f.name: (f.default, f.type) for f in fields(OOPSConfig)}
    p.add_argument("--solver", default=docs["solver"][0], choices=["sinkhorn", "emd", "greedy"])
    p.add_argument(
        "--metric",
        default=docs["metric"][0],
        choices=["sqrt_euclidean", "euclidean", "sqeuclidean", "cosine"],
    )
    p.add_argument("--atoms", default=docs["atoms"][0], choices=["transitions", "states"])
    p.add_argument("--reg", type=float, default=docs["reg"][0], help="Sinkhorn lambda")
    p.add_argument("--json", action="store_true", help="one JSON line per episode")
    p.set_defaults(run=_run_reward)


def _run_reward(args: argparse.Namespace) -> int:
    path = args.demos or bundled_demos("Hopper-v5-scripted")
    data = demos.load(path)
    episodes = [e.observations for e in data.episodes]
    if not 0 <= args.expert < len(episodes):
        raise ValueError(f"--expert {args.expert} out of range: the file has {len(episodes)}")
    expert = episodes[args.expert]
    learners: list[tuple[str, np.ndarray]] = []
    if args.learners is None:
        noisy = expert + np.random.default_rng(0).normal(0.0, 0.01, expert.shape)
        others = [i for i in range(len(episodes)) if i != args.expert]
        learners.append(("expert + N(0, 0.01^2) noise", noisy))
        if others:
            learners.append((f"episode {others[0]}", episodes[others[0]]))
            learners.append((f"episode {others[-1]}", episodes[others[-1]]))
    else:
        for i in args.learners:
            if not 0 <= i < len(episodes):
                raise ValueError(f"learner {i} out of range: the file has {len(episodes)}")
            learners.append((f"episode {i}", episodes[i]))
    if args.rewarder == "pwil":
        rewarder = PWIL([expert])
    else:
        cfg = OOPSConfig(solver=args.solver, metric=args.metric, atoms=args.atoms, reg=args.reg)
        rewarder = OOPS([expert], cfg)
    if not args.json:
        print(f"{data.env_id} demos from {path}: expert = episode {args.expert}")
        print(
            f"{'learner':30s} {'OT distance':>12s} {'mean reward':>12s} "
            f"{'iters':>6s} {'conv':>5s} {'ms':>8s}"
        )
    for name, obs in learners:
        start = time.perf_counter()
        out = rewarder(obs)
        ms = 1e3 * (time.perf_counter() - start)
        row = {
            "learner": name,
            "ot_distance": out.distance,
            "mean_reward": float(out.rewards.mean()),
            "iterations": out.coupling.iterations,
            "converged": out.coupling.converged,
            "marginal_error": out.coupling.marginal_error,
            "ms": ms,
        }
        if args.json:
            print(json.dumps(row))
        else:
            print(
                f"{name:30s} {out.distance:12.4f} {row['mean_reward']:12.4f} "
                f"{out.coupling.iterations!s:>6s} {out.coupling.converged!s:>5s} {ms:8.1f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
