"""The ``ilfo`` command line: thin wrappers over the library."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import shutil
import sys
import time
import warnings
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path
from typing import TextIO

import numpy as np

from ilfo import demos
from ilfo.compilation_cache import enable_compilation_cache
from ilfo.config import add_dataclass_arguments, flag_name, overrides_from_args
from ilfo.paths import bundled_demos
from ilfo.rewards import OOPS, PWIL, OOPSConfig


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ilfo`` console script."""
    parser = argparse.ArgumentParser(
        prog="ilfo",
        description="Imitation learning from observation (OOPS and its peers).",
        epilog="Compiled programs are cached in ~/.cache/ilfo/jax ($XDG_CACHE_HOME/ilfo/jax), so "
        "later starts of the same setting compile less; ILFO_COMPILATION_CACHE=DIR moves the "
        "cache, ILFO_COMPILATION_CACHE=off turns it off.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    _add_train_parser(sub)
    _add_eval_parser(sub)
    _add_plot_parser(sub)
    _add_expert_parser(sub)
    _add_reward_parser(sub)
    _add_demos_parser(sub)
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():  # restores the default display on the way out
            warnings.showwarning = _show_warning
            enable_compilation_cache()  # before the first compilation; see its module
            return args.run(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"ilfo: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # a read-only or full disk, a path under a file: what and where
        where = f"{err.filename}: " if err.filename else ""
        print(f"ilfo: error: {where}{err.strerror or err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """A warning for a command-line user: one line, without the source line it came from."""
    print(f"ilfo: warning: {message}", file=sys.stderr if file is None else file)


def _add_train_parser(sub: argparse._SubParsersAction) -> None:
    from ilfo.agents import TD3Config
    from ilfo.algos import AGENT_PARTS, PART_CONFIGS, REWARD_PARTS, algos_using
    from ilfo.training import TrainConfig

    p = sub.add_parser(
        "train",
        help="Train a policy (default: OOPS+TD3 on Hopper-v5 from one shipped expert demo).",
        description=(
            "Train a policy from state-only demonstrations (or on the task reward for td3/sac). "
            "Writes runs/<env>__<algo>__<seed>__<time>/ with config.json, metrics.csv, tb/ "
            "(TensorBoard), checkpoints/, policy.msgpack (the final policy), best_policy.msgpack "
            "and best_policy.json (the best-evaluated one) and learning_curve.png. Ctrl-C "
            "checkpoints; --resume RUN_DIR continues exactly where the run stopped. Every "
            "setting, the agent's and the rewarder's included, is recorded in config.json."
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
    paper, fast = TD3Config.paper(), TD3Config.fast()
    preset_defaults = {
        f.name: _show(getattr(paper, f.name))
        if getattr(paper, f.name) == getattr(fast, f.name)
        else f"paper {_show(getattr(paper, f.name))}, fast {_show(getattr(fast, f.name))}"
        for f in dataclasses.fields(TD3Config)
    }
    for name, part in {**AGENT_PARTS, **REWARD_PARTS}.items():
        algos = ", ".join(algos_using(name))
        title = f"{part.title} ({algos}{'; overrides the --preset' * (name == 'td3')})"
        group = p.add_argument_group(title, part.description)
        defaults = preset_defaults if name == "td3" else None
        add_dataclass_arguments(
            group, PART_CONFIGS[name], part.set_by_trainer, prefix=name, defaults=defaults
        )
    p.set_defaults(run=_run_train)


def _show(value: object) -> str:
    return " ".join(map(str, value)) if isinstance(value, tuple) else str(value)


def _command() -> str:
    """How the user can start this program again from the same directory: ``ilfo`` where that
    is what the shell finds, else the path it was started by (the README's commands never
    activate the virtual environment: ``.venv/bin/ilfo``), else ``python -m ilfo.cli``."""
    started = sys.argv[0] if sys.argv else ""
    if Path(started).name == "ilfo":
        found = shutil.which("ilfo")
        if found and Path(found).resolve() == Path(started).resolve():
            return "ilfo"
        return shlex.quote(started)
    return f"{shlex.quote(sys.executable)} -m ilfo.cli"


def _run_train(args: argparse.Namespace) -> int:
    from ilfo.algos import PART_CONFIGS
    from ilfo.training import TrainConfig, Trainer, create_run_dir, run_name

    overrides = overrides_from_args(args, TrainConfig)
    groups = {
        name: overrides_from_args(args, cls, prefix=name) for name, cls in PART_CONFIGS.items()
    }
    groups = {name: given for name, given in groups.items() if given}
    if args.resume:
        extra = [flag_name(k) for k in overrides if k != "steps"]
        extra += [flag_name(k, name) for name, given in groups.items() for k in given]
        if extra:
            raise ValueError(f"--resume takes its config from the run; drop {', '.join(extra)}")
        trainer = Trainer.resume(
            args.resume, progress=not args.no_progress, steps=overrides.get("steps")
        )
    else:
        config = TrainConfig(**overrides)
        # A group's flags change the preset's (or the default) config of that part; groups
        # with no flag given stay None, i.e. the defaults.
        config = dataclasses.replace(
            config,
            **{
                name: dataclasses.replace(config.part_config(name), **given)
                for name, given in groups.items()
            },
        )
        run_dir = create_run_dir(config.out, run_name(config))  # new and empty, never shared
        try:
            trainer = Trainer(config, run_dir, progress=not args.no_progress)
        except BaseException:
            run_dir.rmdir()  # nothing was written: a failed start leaves no directory behind
            raise
    trainer.resume_command = f"{_command()} train --resume {shlex.quote(str(trainer.run_dir))}"
    print(f"run directory: {trainer.run_dir}")
    print(trainer.checkpoint_plan())
    run_dir = trainer.train()
    final = trainer.last_eval
    print(f"done: {run_dir}  last evaluation: {json.dumps(final)}")
    return 0


def _add_eval_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval",
        help="Evaluate a run's final policy (deterministic episodes).",
        description=(
            "Evaluate a run's final policy (policy.msgpack, or its last checkpoint's while the "
            "run has not finished): the paper's fixed-horizon score and the standard return, "
            "both normalised by the demos' return, and the OT distance to the first demo."
        ),
    )
    p.add_argument("run_dir", help="a run directory written by `ilfo train`")
    p.add_argument("--episodes", type=int, default=10, help="episodes to run (default 10)")
    p.add_argument(
        "--best", action="store_true", help="evaluate best_policy.msgpack instead of the final one"
    )
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

    result = evaluate_run(
        Path(args.run_dir), episodes=args.episodes, video=args.video, best=args.best
    )
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>20s}: {value}")
    return 0


def _add_expert_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("expert", help="Train, export and evaluate SAC experts.")
    esub = p.add_subparsers(dest="expert_command", required=True)
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
        default=10_000,
        help="steps between evaluations (default 10,000; a resumed run keeps its own)",
    )
    t.add_argument(
        "--eval-episodes",
        type=int,
        default=10,
        help="episodes per evaluation (default 10; fewer for slow envs such as Minitaur)",
    )
    t.add_argument(
        "--reward-scale",
        type=float,
        default=None,
        help="SAC reward scale (default 16 for the Minitaur tasks, whose per-step rewards are "
        "tiny, else 1; a resumed run keeps its own)",
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
    t.add_argument("--resume", action="store_true", help="continue the existing run")
    t.add_argument("--run-dir", default=None, help="run directory (default: see above)")
    t.add_argument(
        "--checkpoint-every",
        type=int,
        default=25_000,
        help="steps between checkpoints (default 25,000)",
    )
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.set_defaults(run=_run_expert_train)
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
    e = esub.add_parser("eval", help="Mean and std return of a shipped (or given) expert.")
    e.add_argument("env", help="environment id with a shipped expert, or an expert directory")
    e.add_argument(
        "--episodes", type=int, default=10, help="episodes, seeds 1000, 1001, ... (default 10)"
    )
    e.add_argument("--json", action="store_true", help="one JSON line")
    e.set_defaults(run=_run_expert_eval)


def _run_expert_train(args: argparse.Namespace) -> int:
    from ilfo.agents import SACConfig
    from ilfo.experts import expert_reward_scale
    from ilfo.training import TrainConfig, Trainer

    run_dir = Path(args.run_dir or Path("runs") / "experts" / f"{args.env}__sac__{args.seed}")
    if args.resume:
        if args.reward_scale is not None:
            raise ValueError("--reward-scale cannot change on --resume: the run keeps its own")
        if args.healthy_angle_range is not None:
            raise ValueError(
                "--healthy-angle-range cannot change on --resume: the run keeps its own"
            )
        trainer = Trainer.resume(run_dir, progress=not args.no_progress, steps=args.steps)
    else:
        if (run_dir / "config.json").exists():
            raise ValueError(f"{run_dir} exists: continue it with --resume, or pass --run-dir")
        scale = expert_reward_scale(args.env) if args.reward_scale is None else args.reward_scale
        config = TrainConfig(
            env=args.env,
            algo="sac",
            sac=SACConfig(reward_scale=scale),
            best_by="return",
            healthy_angle_range=args.healthy_angle_range,  # a list: TrainConfig makes it a tuple
            seed=args.seed,
            steps=args.steps or 1_000_000,
            eval_every=args.eval_every,
            eval_episodes=args.eval_episodes,
            checkpoint_every=args.checkpoint_every,
        )
        trainer = Trainer(config, run_dir, progress=not args.no_progress)
    trainer.resume_command = (
        f"{_command()} expert train {shlex.quote(args.env)} --resume --run-dir "
        f"{shlex.quote(str(run_dir))}"
    )
    print(f"run directory: {run_dir}")
    print(trainer.checkpoint_plan())
    trainer.train()
    print(f"done: {json.dumps(trainer.last_eval)}")
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

    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    result = evaluate_expert(args.env, args.episodes)
    print(
        json.dumps(result)
        if args.json
        else f"{result['env_id']}: return {result['return_mean']:.1f} +- {result['return_std']:.1f}"
        f" (fixed-horizon score {result['score_mean']:.1f}) over {args.episodes} episodes"
    )
    return 0


def _add_plot_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plot", help="Plot evaluation curves of runs (mean and spread over seeds).")
    p.add_argument("run_dirs", nargs="+", help="run directories")
    p.add_argument(
        "--out", default="learning_curves.png", help="output image (default learning_curves.png)"
    )
    p.add_argument(
        "--metric",
        default=None,
        help="a metrics.csv column (default: eval_score_norm, else eval_score)",
    )
    p.set_defaults(run=_run_plot)


def _run_plot(args: argparse.Namespace) -> int:
    from ilfo.training import plot_runs

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
    p.add_argument(
        "--rewarder", choices=["oops", "pwil"], default="oops", help="reward (default oops)"
    )
    docs = {f.name: (f.default, f.type) for f in fields(OOPSConfig)}
    p.add_argument(
        "--solver",
        default=docs["solver"][0],
        choices=["sinkhorn", "emd", "greedy"],
        help=f"OOPS coupling (default {docs['solver'][0]})",
    )
    p.add_argument(
        "--metric",
        default=docs["metric"][0],
        choices=["sqrt_euclidean", "euclidean", "sqeuclidean", "cosine"],
        help=f"OOPS ground cost (default {docs['metric'][0]})",
    )
    p.add_argument(
        "--atoms",
        default=docs["atoms"][0],
        choices=["transitions", "states"],
        help=f"OOPS atoms: (s, s') or s (default {docs['atoms'][0]})",
    )
    p.add_argument(
        "--reg",
        type=float,
        default=docs["reg"][0],
        help=f"Sinkhorn lambda (default {docs['reg'][0]})",
    )
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


def _add_demos_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demos",
        help="Inspect and convert demonstration files (ilfo .npz, Minari, D4RL, imitation).",
    )
    dsub = p.add_subparsers(dest="demos_command", required=True)
    i = dsub.add_parser(
        "info",
        help="Episodes, lengths, dims, returns, env id and provenance of a demo file.",
        description="Describe a demonstration file of any format `ilfo demos convert` reads.",
    )
    i.add_argument("file", help="ilfo/imitation .npz, Minari/D4RL .hdf5, or a Minari dataset dir")
    i.add_argument("--json", action="store_true", help="print one JSON object")
    i.set_defaults(run=_run_demos_info)
    c = dsub.add_parser(
        "convert",
        help="Convert a Minari, D4RL or imitation file (or an ilfo one) to ilfo's .npz.",
        description=(
            "Read IN (ilfo or imitation .npz, Minari or D4RL HDF5, Minari dataset directory; the "
            "format is detected from the contents) and write OUT in ilfo's .npz format. D4RL and "
            "imitation files do not record their environment: pass --env-id."
        ),
    )
    c.add_argument("input", metavar="IN", help="demonstration file or Minari dataset directory")
    c.add_argument("output", metavar="OUT", help="ilfo .npz to write")
    c.add_argument("--env-id", default=None, help="environment id to record (overrides IN's)")
    c.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    c.set_defaults(run=_run_demos_convert)
    k = dsub.add_parser(
        "collect",
        help="Deterministic full-length rollouts of an expert policy, saved as ilfo .npz.",
        description=(
            "Roll out an exported expert (a directory with expert.json and policy.msgpack, or an "
            "env id with a shipped expert) deterministically for the full horizon. Observations "
            "are what a learner sees; actions and rewards are kept for analysis only."
        ),
    )
    k.add_argument("--expert", required=True, help="expert directory or env id")
    k.add_argument("--env", default=None, help="check that the expert is for this env")
    k.add_argument(
        "-n", "--episodes", type=int, default=10, help="episodes to collect (default 10)"
    )
    k.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    k.add_argument("--out", required=True, help="ilfo .npz to write")
    k.add_argument(
        "--keep-falls",
        action="store_true",
        help="keep episodes in which the expert falls (default: skip them, try the next seed)",
    )
    k.set_defaults(run=_run_demos_collect)


def _run_demos_collect(args: argparse.Namespace) -> int:
    from ilfo.experts import collect_demos, load_expert

    expert = load_expert(args.expert)
    if args.env and args.env != expert.config.env:
        raise ValueError(f"the expert is for {expert.config.env}, not {args.env}")
    episodes = collect_demos(
        expert, args.episodes, args.out, first_seed=args.seed, skip_falls=not args.keep_falls
    )
    returns = np.array([e.task_score for e in episodes])
    print(
        f"wrote {args.out}: {len(episodes)} episodes of {len(episodes[0].observations) - 1} "
        f"steps, return {returns.mean():.1f} +- {returns.std():.1f} (fixed-horizon score)"
    )
    return 0


def _run_demos_info(args: argparse.Namespace) -> int:
    summary = demos.summarize(demos.load_any(args.file))
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"{args.file} ({demos.detect_format(args.file)})")
    rows = [
        ("env id", summary["env_id"] or "(not recorded)"),
        ("episodes", summary["episodes"]),
        ("transitions", summary["transitions"]),
        (
            "length (T)",
            f"min {summary['length_min']}  mean {summary['length_mean']:.1f}  "
            f"max {summary['length_max']}",
        ),
        ("obs dim", summary["obs_dim"]),
        ("action dim", "(no actions)" if summary["action_dim"] is None else summary["action_dim"]),
    ]
    if summary["return_mean"] is None:
        rows.append(("return", "(no rewards)"))
    else:
        rows.append(
            (
                "return",
                f"mean {summary['return_mean']:.2f}  std {summary['return_std']:.2f}  "
                f"min {summary['return_min']:.2f}  max {summary['return_max']:.2f}",
            )
        )
    rows.append(("provenance", json.dumps(summary["provenance"], sort_keys=True)))
    for key, value in rows:
        print(f"{key:>12s}: {value}")
    return 0


def _run_demos_convert(args: argparse.Namespace) -> int:
    out = Path(args.output)
    if out.suffix != ".npz":
        raise ValueError(f"OUT must end in .npz, got {out}")
    if out.exists() and not args.force:
        raise ValueError(f"{out} exists: pass --force to overwrite it")
    data = demos.load_any(args.input)
    env_id = args.env_id or data.env_id
    if not env_id:
        raise ValueError(f"{args.input} does not record its environment: pass --env-id")
    provenance = dict(data.provenance)
    if args.env_id and data.env_id and data.env_id != args.env_id:
        provenance["env_id_overridden_from"] = data.env_id
    demos.save(out, data.episodes, env_id, provenance)
    print(f"wrote {out}: {len(data.episodes)} episodes of {env_id}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
