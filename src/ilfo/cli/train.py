"""``ilfo train``, ``ilfo eval`` and ``ilfo plot``."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ilfo.cli._common import _command
from ilfo.config import add_dataclass_arguments, flag_name, overrides_from_args

if TYPE_CHECKING:
    from ilfo.algos import AgentPart
    from ilfo.training import DemoSource, TrainConfig


def _add_train_parser(sub: argparse._SubParsersAction) -> None:
    from ilfo.algos import AGENT_PARTS, PART_CONFIGS, REWARD_PARTS, algos_using
    from ilfo.training import TrainConfig

    p = sub.add_parser(
        "train",
        help="Train a policy (default: OOPS+TD3 on Hopper-v5 from one shipped expert demo).",
        usage="%(prog)s [options]",  # the flags are too many to list: the description's first
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_dataclass_arguments(p, TrainConfig)
    p.add_argument(
        "--resume",
        metavar="RUN_DIR",
        default=None,
        help="continue a run from its last checkpoint (--steps may extend it)",
    )
    p.add_argument(
        "--config",
        metavar="FILE.json",
        default=None,
        help="start from the settings of this file (a run's config.json, or a hand-written "
        'subset: a part\'s dict, e.g. {"td3": {"batch_size": 256}}, changes single fields '
        "of its default); flags override it (a run's recorded contact forces give way to "
        "the default of another --env or --algo)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    for name, part in {**AGENT_PARTS, **REWARD_PARTS}.items():
        algos = ", ".join(algos_using(name))
        presets = _preset_defaults(AGENT_PARTS[name]) if name in AGENT_PARTS else None
        overrides = "; overrides the --preset" if presets else ""
        group = p.add_argument_group(f"{part.title} ({algos}{overrides})", part.description)
        add_dataclass_arguments(
            group, PART_CONFIGS[name], part.set_by_trainer, prefix=name, defaults=presets
        )
    p.description = _train_description(p, dataclasses.asdict(TrainConfig()))
    p.set_defaults(run=_run_train)


def bar_fields() -> str:
    """What the progress bar's fields mean (``training.console.bar_postfix`` sets them)."""
    from ilfo.algos import ALGOS

    task_reward = [name for name, recipe in ALGOS.items() if not recipe.imitation]
    return (
        "sps: steps/s of the last episode, updates included; proxy: the imitation reward's "
        "return of the last training episode (the task reward's for "
        f"{', '.join(task_reward)}); eval: the last evaluation's (normalised) score"
    )


TRAIN_DESCRIPTION = (
    "Train a policy from state-only demonstrations (or on the task reward for td3/sac). "
    "Writes runs/<env>__<algo>__<seed>__<time>/ with config.json, metrics.csv, tb/ "
    "(TensorBoard), checkpoints/, policy.msgpack (the final policy), best_policy.msgpack "
    "and best_policy.json (the best-evaluated one) and learning_curve.png. Ctrl-C "
    "checkpoints; --resume RUN_DIR continues exactly where the run stopped. Every "
    "setting, the agent's and the rewarder's included, is recorded in config.json."
)

COMMON_TRAIN_FLAGS: dict[str, str] = {
    "--env ENV": "the task",
    "--algo ALGO": "the algorithm, one of the choices below",
    "--demos FILE.npz": "the demo file (none: the env's shipped expert demos)",
    "--num-demos N": "how many of its demos to imitate (the first N)",
    "--steps N": "environment steps in total",
    "--preset {paper,fast}": "agent sizes: the paper's networks, or smaller",
    "--seed N": "seed of everything",
    "--out DIR": "where run directories go",
    "--resume RUN_DIR": "continue a run from its last checkpoint",
    "--config FILE.json": "start from a file's settings (a run's config.json)",
}
"""The options most runs set, listed first in ``ilfo train --help``, a short line each (with
its default, read off the parser); their full help follows with the others."""


def _train_description(parser: argparse.ArgumentParser, defaults: dict[str, Any]) -> str:
    """The description, then ``COMMON_TRAIN_FLAGS`` as a short list (each checked to be one of
    ``parser``'s flags; with its default from ``defaults``, by the flag's field), then where
    the rest are."""
    import textwrap

    actions = {flag: action for action in parser._actions for flag in action.option_strings}
    unknown = [name for name in COMMON_TRAIN_FLAGS if name.split()[0] not in actions]
    if unknown:  # a renamed flag: the short list must not name one that is gone
        raise AssertionError(f"COMMON_TRAIN_FLAGS names no flag of ilfo train: {unknown}")
    width = max(len(name) for name in COMMON_TRAIN_FLAGS) + 2
    lines = [textwrap.fill(TRAIN_DESCRIPTION, 78), "", "Common options:"]
    for name, text in COMMON_TRAIN_FLAGS.items():
        default = defaults.get(actions[name.split()[0]].dest)
        if default is not None:
            shown = f"{default:,}" if isinstance(default, int) else default
            text += f" (default {shown})"
        lines.append(f"  {name:<{width}}{text}")
    lines += ["", textwrap.fill(f"The progress bar's fields: {bar_fields()}.", 78), ""]
    lines.append(
        textwrap.fill(
            "All of the options follow: the run's own, then each agent's and reward's, "
            "grouped by part (--td3-*, --oops-*, ...).",
            78,
        )
    )
    return "\n".join(lines)


def _preset_defaults(part: AgentPart) -> dict[str, str] | None:
    """An agent part's defaults as ``--help`` shows them where its ``--preset``s differ
    ('paper X, fast Y' for the fields that differ); None where the presets build one config."""
    paper, fast = part.default("paper"), part.default("fast")
    if paper == fast:
        return None
    return {
        f.name: _show(getattr(paper, f.name))
        if getattr(paper, f.name) == getattr(fast, f.name)
        else f"paper {_show(getattr(paper, f.name))}, fast {_show(getattr(fast, f.name))}"
        for f in dataclasses.fields(part.config)
    }


def _show(value: object) -> str:
    return " ".join(map(str, value)) if isinstance(value, tuple) else str(value)


def settings_from_args(
    config_file: str | None,
    overrides: dict[str, Any],
    groups: dict[str, dict[str, Any]],
    drop: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Settings (``config_from_settings``'s input) from the settings of ``config_file`` (if
    any; its keys in ``drop`` left out, and its parts that are None), changed by the flags
    given (``overrides``: TrainConfig fields; ``groups``: single fields of a part, by name).
    A run's config.json records the contact forces its env and algo observed: where the flags
    change (or ``drop`` leaves out) the file's env or algo, that choice is left out too (the new
    pair's default) unless a flag sets it."""
    from ilfo.training import read_settings, settings_for_new_runs

    settings: dict[str, Any] = {}
    if config_file is not None:
        settings = read_settings(config_file)
        # A flag that changes the file's env or algo replaces it, as ``drop`` does.
        changed = tuple(
            k for k in ("env", "algo") if k in overrides and overrides[k] != settings.get(k)
        )
        settings = settings_for_new_runs(settings, (*drop, *changed))
    settings.update(overrides)
    for name, given in groups.items():
        settings[name] = {**(settings.get(name) or {}), **given}
    return settings


def config_from_args(
    config_file: str | None, overrides: dict[str, Any], groups: dict[str, dict[str, Any]]
) -> TrainConfig:
    """The run's config: ``settings_from_args`` built into a ``TrainConfig``."""
    from ilfo.training import config_from_settings

    source = "the command line" if config_file is None else f"{config_file} and the command line"
    return config_from_settings(settings_from_args(config_file, overrides, groups), source)


def part_flags(args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """The part flags given (``--td3-*``, ``--oops-*``, ...), as {part: {field: value}}."""
    from ilfo.algos import PART_CONFIGS

    groups = {
        name: overrides_from_args(args, cls, prefix=name) for name, cls in PART_CONFIGS.items()
    }
    return {name: given for name, given in groups.items() if given}


def _run_train(args: argparse.Namespace) -> int:
    from ilfo.training import TrainConfig, Trainer, create_run_dir, run_name

    overrides = overrides_from_args(args, TrainConfig)
    groups = part_flags(args)
    progress = not args.no_progress
    if args.resume:
        extra = [flag_name(k) for k in overrides if k != "steps"]
        extra += [flag_name(k, name) for name, given in groups.items() for k in given]
        extra += ["--config"] * (args.config is not None)
        if extra:
            raise ValueError(f"--resume takes its config from the run; drop {', '.join(extra)}")
        trainer = Trainer.resume(args.resume, progress=progress, steps=overrides.get("steps"))
    else:
        config = config_from_args(args.config, overrides, groups)
        run_dir = create_run_dir(config.out, run_name(config))  # new and empty, never shared
        try:
            trainer = Trainer(config, run_dir, progress=progress)
        except BaseException:
            run_dir.rmdir()  # nothing was written: a failed start leaves no directory behind
            raise
    trainer.resume_command = f"{_command()} train --resume {shlex.quote(str(trainer.run_dir))}"
    summary = start_summary(
        trainer.config, trainer.run_dir, trainer.demo_source, trainer.step, progress=progress
    )
    print(f"{summary}\n  {trainer.checkpoint_plan()}")
    run_dir = trainer.train()
    final = trainer.last_eval
    print(f"done: {run_dir}  last evaluation: {json.dumps(final)}")
    return 0


def start_summary(
    config: TrainConfig,
    run_dir: Path,
    demos: DemoSource | None,
    step: int = 0,
    *,
    progress: bool = False,
) -> str:
    """What ``ilfo train`` prints as it starts (or resumes at ``step``): the algo, env, preset
    and seed, the demos, the steps, the expected duration where the algo has a measured rate
    (``estimates.run_core_seconds``, the one estimate of a run's compute), the run directory
    and, with ``progress``, what the progress bar's fields mean."""
    from ilfo.experiments.estimates import run_core_seconds

    lines = [f"{config.algo} on {config.env}, {config.preset} preset, seed {config.seed}"]
    if demos is None:
        lines.append(f"  demos: none ({config.algo} learns from the task reward)")
    else:
        first = "demo" if demos.num_demos == 1 else f"{demos.num_demos} demos"
        lines.append(f"  demos: {demos.path} (its first {first})")
    resumed = f", from step {step:,}" if step else ""
    lines.append(f"  steps: {config.steps:,}{resumed}; evaluated every {config.eval_every:,}")
    settings = {"algo": config.algo, "env": config.env, "preset": config.preset}
    seconds = run_core_seconds(
        {**settings, "updates_per_step": config.updates_per_step}, config.steps - step
    )
    if seconds:
        lines.append(
            f"  expected: ~{_duration(seconds)} of one core (the measured rates of "
            "docs/benchmarks.md; longer beside other work)"
        )
    lines.append(f"  writes: {run_dir}")
    if progress:
        lines.append(f"  progress bar: {bar_fields()}")
    return "\n".join(lines)


def _duration(seconds: float) -> str:
    if seconds >= 5400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 60:.0f} min" if seconds >= 90 else f"{seconds:.0f} s"


def _add_eval_parser(sub: argparse._SubParsersAction) -> None:
    from ilfo.training.config import MAX_EVAL_EPISODES  # imported by `ilfo train`'s parser too

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
    p.add_argument(
        "--episodes",
        type=int,
        default=10,
        help=f"episodes to run (default 10, at most {MAX_EVAL_EPISODES:,})",
    )
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


def _add_plot_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plot",
        help="Plot evaluation curves of runs (mean and spread over seeds).",
        description=(
            "Plot evaluation curves of runs: the mean and min-max band over seeds, one curve per "
            "env, algo, demos and settings (runs trained otherwise, e.g. at another --preset, are "
            "separate curves, each label naming its settings)."
        ),
    )
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


def _add_snapshot_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "snapshot",
        help="Copy a run without its replay buffer (a few MB: to keep in git or move it).",
        description=(
            "Copy RUN_DIR's config, metrics, policies and newest checkpoint, without the "
            "replay buffer, to OUT. `ilfo train --resume OUT` continues it: the buffer is "
            "first refilled by --start-steps steps of the current policy (no updates), so the "
            "continuation is close to, not exactly, the uninterrupted run's. An on-policy run "
            "(sil) keeps its buffer, the batch pending since its last update, and continues "
            "exactly. For runs and experts that outlive a machine."
        ),
    )
    p.add_argument("run_dir", help="the run directory")
    p.add_argument("out", help="the snapshot's directory (must not exist)")
    p.set_defaults(run=_run_snapshot)


def _run_snapshot(args: argparse.Namespace) -> int:
    from ilfo.training.checkpoint import snapshot_run

    out = snapshot_run(args.run_dir, args.out)
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    print(f"wrote {out} ({size / 2**20:.1f} MiB); continue it with `ilfo train --resume {out}`")
    return 0
