"""``ilfo expert train | export | eval``."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
from pathlib import Path

from ilfo.cli._common import _command


def _add_expert_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("expert", help="Train, export and evaluate SAC experts.")
    esub = p.add_subparsers(dest="expert_command", required=True)
    _add_expert_train_parser(esub)
    _add_expert_export_parser(esub)
    e = esub.add_parser("eval", help="Mean and std return of a shipped (or given) expert.")
    e.add_argument("env", help="environment id with a shipped expert, or an expert directory")
    e.add_argument(
        "--episodes", type=int, default=10, help="episodes, seeds 1000, 1001, ... (default 10)"
    )
    e.add_argument("--json", action="store_true", help="one JSON line")
    e.set_defaults(run=_run_expert_eval)


def _add_expert_train_parser(esub: argparse._SubParsersAction) -> None:
    t = esub.add_parser(
        "train",
        help="SAC on the task reward, checkpointed and resumable in segments.",
        description=(
            "Train a SAC expert on the task reward in runs/experts/<ENV>__sac__<seed>/ (or "
            "--run-dir). Standard episodes (termination handled), evaluated every --eval-every "
            "steps on --eval-episodes deterministic episodes; the policy of the best standard "
            "return (which stops at the first fall) is what `ilfo expert export` ships. Stop "
            "any time (Ctrl-C checkpoints) and continue with --resume, possibly with a larger "
            "--steps."
        ),
    )
    t.add_argument("env", help="environment id, e.g. Hopper-v5")
    t.add_argument("--steps", type=int, default=None, help="total steps (default 1,000,000)")
    t.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    t.add_argument(
        "--eval-every",
        type=int,
        default=None,
        help="steps between evaluations (default 10,000; a resumed run keeps its own)",
    )
    t.add_argument(
        "--eval-episodes",
        type=int,
        default=None,
        help="episodes per evaluation (default 10; fewer for slow envs such as Minitaur; a "
        "resumed run keeps its own)",
    )
    t.add_argument(
        "--reward-scale",
        type=float,
        default=None,
        help="SAC reward scale (default 16 for the Minitaur tasks, whose per-step rewards are "
        "tiny, else 1; a resumed run keeps its own)",
    )
    t.add_argument(
        "--gamma",
        type=float,
        default=None,
        help="SAC discount (default 0.99). Higher values weigh survival further ahead: on "
        "MinitaurDuck, where losing the duck ends the episode, 0.99 looks ~100 steps ahead of a "
        "1,000-step task (docs/experts.md); a resumed run keeps its own",
    )
    t.add_argument(
        "--healthy-angle-range",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        default=None,
        help="train with a stricter torso angle range (radians; Hopper, Walker2d): the expert "
        "learns to keep a margin from a fall; demos are still recorded in the standard env "
        "(default: the env's own range; a resumed run keeps its own)",
    )
    t.add_argument(
        "--contact-forces",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="Ant-v5, Humanoid-v5: whether the expert observes the contact forces that end their "
        "observations (default: it does). Without them SAC learns from the 27 (Ant) or 270 "
        "(Humanoid) other columns, as on the paper's v2 tasks, whose contact forces were all "
        "zero; its demos still record the full observation (a resumed run keeps its own)",
    )
    t.add_argument("--resume", action="store_true", help="continue the existing run")
    t.add_argument("--run-dir", default=None, help="run directory (default: see above)")
    t.add_argument(
        "--checkpoint-every",
        type=int,
        default=None,
        help="steps between checkpoints (default 25,000; a resumed run keeps its own)",
    )
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.set_defaults(run=_run_expert_train)


def _add_expert_export_parser(esub: argparse._SubParsersAction) -> None:
    x = esub.add_parser("export", help="Export a run's policy as the env's shipped expert.")
    x.add_argument("run_dir", help="the expert's run directory")
    x.add_argument("--out", default=None, help="expert directory (default data/experts/<env>)")
    x.add_argument("-n", "--num-demos", type=int, default=10, help="demos to collect (default 10)")
    x.add_argument(
        "--which",
        choices=["best", "latest"],
        default="best",
        help="the best-evaluated policy or the last checkpoint's",
    )
    x.add_argument(
        "--keep-falls",
        action="store_true",
        help="keep demos in which the expert falls (default: skip them, try the next seed)",
    )
    x.add_argument(
        "--note",
        default=None,
        help="a sentence for the card, e.g. why an expert short of the paper's is shipped",
    )
    x.set_defaults(run=_run_expert_export)


def _run_expert_train(args: argparse.Namespace) -> int:
    from ilfo.agents import SACConfig
    from ilfo.experts import expert_reward_scale
    from ilfo.training import TrainConfig, Trainer, read_run_config

    run_dir = Path(args.run_dir or Path("runs") / "experts" / f"{args.env}__sac__{args.seed}")
    if args.resume:
        kept = {
            "--reward-scale": args.reward_scale,
            "--healthy-angle-range": args.healthy_angle_range,
            "--gamma": args.gamma,
            "--contact-forces": args.contact_forces,
            "--eval-every": args.eval_every,
            "--eval-episodes": args.eval_episodes,
            "--checkpoint-every": args.checkpoint_every,
        }
        for flag, value in kept.items():
            if value is not None:
                raise ValueError(f"{flag} cannot change on --resume: the run keeps its own")
        recorded = read_run_config(run_dir).get("env")
        if recorded != args.env:
            raise ValueError(f"{run_dir} trains an expert for {recorded}, not {args.env}")
        trainer = Trainer.resume(run_dir, progress=not args.no_progress, steps=args.steps)
    else:
        if (run_dir / "config.json").exists():
            raise ValueError(f"{run_dir} exists: continue it with --resume, or pass --run-dir")
        scale = expert_reward_scale(args.env) if args.reward_scale is None else args.reward_scale
        sac = SACConfig(reward_scale=scale)
        if args.gamma is not None:
            if not 0.0 < args.gamma < 1.0:
                raise ValueError(f"--gamma must be in (0, 1), got {args.gamma}")
            sac = dataclasses.replace(sac, gamma=args.gamma)
        config = TrainConfig(
            env=args.env,
            algo="sac",
            sac=sac,
            best_by="return",
            healthy_angle_range=args.healthy_angle_range,  # a list: TrainConfig makes it a tuple
            contact_forces=args.contact_forces,
            seed=args.seed,
            steps=1_000_000 if args.steps is None else args.steps,
            eval_every=10_000 if args.eval_every is None else args.eval_every,
            eval_episodes=10 if args.eval_episodes is None else args.eval_episodes,
            checkpoint_every=25_000 if args.checkpoint_every is None else args.checkpoint_every,
        )
        trainer = Trainer(config, run_dir, progress=not args.no_progress)
    trainer.resume_command = (
        f"{_command()} expert train {shlex.quote(args.env)} --resume --run-dir "
        f"{shlex.quote(str(run_dir))}"
    )
    print(f"run directory: {run_dir}")
    print(trainer.checkpoint_plan())
    trainer.train()
    print(f"done: {json.dumps(trainer.last_eval) if trainer.last_eval else 'no evaluation yet'}")
    return 0


def _run_expert_export(args: argparse.Namespace) -> int:
    from ilfo.experts import export_expert_with_demos

    out, card = export_expert_with_demos(
        args.run_dir,
        args.out,
        args.which,
        args.num_demos,
        skip_falls=not args.keep_falls,
        note=args.note,
    )
    skipped, fell = card["demo_seeds_skipped_for_a_fall"], card["demo_seeds_with_a_fall"]
    print(
        f"wrote {out}: return {card['return_mean']:.1f} +- {card['return_std']:.1f} over "
        f"{card['num_demos']} demos after {card['steps_trained']} steps"
        + (f"; skipped seeds {skipped}, where the expert fell" if skipped else "")
        + (f"; kept demos with a fall (seeds {fell})" if fell else "")
    )
    return 0


def _run_expert_eval(args: argparse.Namespace) -> int:
    from ilfo.experts import evaluate_expert

    result = evaluate_expert(args.env, args.episodes)
    print(
        json.dumps(result)
        if args.json
        else f"{result['env_id']}: return {result['return_mean']:.1f} +- {result['return_std']:.1f}"
        f" (fixed-horizon score {result['score_mean']:.1f}) over {args.episodes} episodes"
    )
    return 0
