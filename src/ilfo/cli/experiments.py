"""``ilfo sweep run | create | status | snapshot``, ``ilfo reproduce``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ilfo.cli._common import Parser, stop_signals_interrupt
from ilfo.config import overrides_from_args

_SPEC_FILE_HELP = (
    'Spec file (JSON or TOML): {"env": [...], "algo": [...], "num_demos": [1, 4, 10], '
    '"seed": "0-4", "config": {"steps": 1000000, "preset": "fast"}, "variants": '
    '{"lambda0.1": {"oops": {"reg": 0.1}}}, "retries": 2}; config may name a settings file '
    "(a run's config.json, whose env, algo, demos, seed and out the sweep sets)."
)


def _add_sweep_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep",
        help="Run many runs (env x algo x demos x seed), resumable; create, show or snapshot "
        "a sweep.",
        description="A sweep directory holds a manifest of runs and each run's directory; "
        "`ilfo sweep run` trains the unfinished ones and can be stopped and started again at "
        "any point without losing work.",
    )
    actions = p.add_subparsers(dest="sweep_command", required=True)
    _add_sweep_run_parser(actions)
    _add_sweep_create_parser(actions)
    _add_sweep_status_and_snapshot_parsers(actions)


def _add_sweep_run_parser(actions: argparse._SubParsersAction) -> None:
    run = actions.add_parser(
        "run",
        allow_abbrev=False,  # --seed is an `ilfo train` flag, not short for --seeds
        help="Create a sweep (from --spec or the axis flags) or continue one, and run it.",
        description=(
            "Run a sweep: every combination of --env, --algo, --num-demos and --seeds (or a "
            "--spec file's axes and named variants), each an `ilfo train` run with the "
            "settings given by any further `ilfo train` flag (e.g. --steps 1000000 --preset "
            "fast --td3-batch-size 256; a part's flags apply to the algos that use that part). "
            "Finished runs are skipped, interrupted ones resume from their checkpoints, failed "
            "ones are retried up to --retries times. With a DIR that holds a sweep and no axes, "
            "continues it; with several such DIRs, continues them as one queue, in their "
            "order (a core that one sweep's last runs leave free takes the next's). Ctrl-C "
            "checkpoints every run and stops."
        ),
        epilog=_SPEC_FILE_HELP,
    )
    run.add_argument(
        "dir",
        nargs="+",
        metavar="DIR",
        help="the sweep directory (created if missing), or several existing ones to continue "
        "as one queue; before any flag",
    )
    _add_spec_arguments(run)
    run.add_argument(
        "--retry-failed",
        action="store_true",
        help="forget the failures of runs that were given up, so that they run again",
    )
    run.add_argument(
        "--only",
        nargs="+",
        default=(),
        metavar="PATTERN",
        help="run only the runs whose names match one of these shell patterns (e.g. "
        "'Hopper-v5__*' '*__pwil-td3__*'); the others are left as they are",
    )
    run.add_argument(
        "--skip",
        nargs="+",
        default=(),
        metavar="PATTERN",
        help="leave out the runs whose names match one of these patterns, for now (e.g. "
        "'Ant-v5__*' while its expert retrains); a later `sweep run` without it runs them",
    )
    _add_backend_arguments(run)
    run.add_argument("--dry-run", action="store_true", help="list the runs and stop")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.set_defaults(run=_run_sweep, takes_train_flags=True)


def _add_sweep_create_parser(actions: argparse._SubParsersAction) -> None:
    create = actions.add_parser(
        "create",
        allow_abbrev=False,
        help="Write a sweep's manifest without running it (to queue it: `ilfo sweep run A B`).",
        description=(
            "Write the manifest of a sweep (from --spec or the axis flags, and any `ilfo "
            "train` flag, as `ilfo sweep run` takes them) and list its runs, without running "
            "any. So a new sweep can be queued behind a running one: stop `ilfo sweep run A` "
            "(Ctrl-C checkpoints its runs) and start `ilfo sweep run A NEW`, which continues "
            "both as one queue. A DIR that holds the same sweep is left as it is (--retries "
            "may change its retries); one that holds another sweep, or other files, is refused."
        ),
        epilog=_SPEC_FILE_HELP,
    )
    create.add_argument(
        "dir", metavar="DIR", help="the new sweep's directory (made if missing); before any flag"
    )
    _add_spec_arguments(create)
    create.set_defaults(run=_run_sweep_create, takes_train_flags=True)


def _add_sweep_status_and_snapshot_parsers(actions: argparse._SubParsersAction) -> None:
    status = actions.add_parser("status", help="Show each run's state and the sweep's progress.")
    status.add_argument(
        "dir", nargs="+", metavar="DIR", help="a sweep directory, or several (one bar over all)"
    )
    status.add_argument("--json", action="store_true", help="one JSON object per run")
    status.set_defaults(run=_run_sweep_status)
    snapshot = actions.add_parser(
        "snapshot",
        help="Copy a stopped sweep without replay buffers (to keep in git or move it).",
        description="Copy a stopped sweep small enough to keep in git or move between "
        "machines: its manifest, attempts, logs and each run's newest checkpoint without the "
        "replay buffer. `ilfo sweep run OUT` continues it: finished runs stay done, "
        "interrupted ones resume (their buffers refilled by start_steps steps of the current "
        "policy; an on-policy run's pending batch is kept, and it continues exactly), runs "
        "without a checkpoint start afresh.",
    )
    snapshot.add_argument("dir", help="a sweep directory, stopped (Ctrl-C checkpoints its runs)")
    snapshot.add_argument("out", help="the new directory")
    snapshot.set_defaults(run=_run_sweep_snapshot)


def _add_spec_arguments(p: argparse.ArgumentParser) -> None:
    """What makes a sweep: a spec file, the axes that change it, and its retries."""
    p.add_argument("--spec", default=None, metavar="FILE", help="a sweep spec file")
    p.add_argument("--env", nargs="+", default=None, help="environment ids")
    p.add_argument("--algo", nargs="+", default=None, help="algorithms")
    p.add_argument("--num-demos", nargs="+", type=int, default=None, help="demo counts")
    p.add_argument("--seeds", nargs="+", default=None, help="seeds, or ranges such as 0-4")
    p.add_argument(
        "--retries", type=int, default=None, help="restarts of a run that failed (default 2)"
    )


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _check_flags_follow_dirs(args: argparse.Namespace) -> None:
    """argparse leaves a positional that is not one of the command's among the unknown
    arguments: a DIR after the flags, or a second DIR of `create`."""
    if args.rest and not args.rest[0].startswith("-"):
        if args.sweep_command == "create":
            raise ValueError(
                f"{args.rest[0]!r} is not a flag: ilfo sweep create takes one DIR, before the flags"
            )
        raise ValueError(
            f"{args.rest[0]!r} is not a flag: the sweep directories go first "
            "(ilfo sweep run DIR [DIR ...] [flags])"
        )


def _train_settings(rest: list[str], command: str) -> dict[str, Any]:
    """The `ilfo train` flags among a sweep's arguments, as sweep-config settings."""
    from ilfo.cli.train import _add_train_parser, part_flags, settings_from_args
    from ilfo.training import TrainConfig

    parser = Parser(prog=f"ilfo sweep {command} DIR [ilfo train flags]")
    commands = parser.add_subparsers()
    _add_train_parser(commands)
    commands.choices["train"].help_command = "ilfo train"  # its prog is no command
    args = parser.parse_args(["train", *rest])
    if args.resume is not None:
        raise ValueError("a sweep's runs resume themselves (ilfo sweep run): drop --resume")
    # The sweep's axes and directory decide these, whatever the config file says.
    drop = ("env", "algo", "num_demos", "seed", "out")
    overrides = overrides_from_args(args, TrainConfig)
    return settings_from_args(args.config, overrides, part_flags(args), drop)


def _spec_from_args(args: argparse.Namespace, root: Path, rest: list[str]) -> Any:
    import dataclasses

    from ilfo.experiments import SweepSpec, open_sweep, parse_seeds
    from ilfo.experiments.sweep import MANIFEST_FILE, merge_settings
    from ilfo.files import read_settings_file

    axes = {
        "env": args.env,
        "algo": args.algo,
        "num_demos": args.num_demos,
        "seed": None if args.seeds is None else parse_seeds(args.seeds),
    }
    given = {k: v for k, v in axes.items() if v is not None}
    manifest = root / MANIFEST_FILE
    if args.spec is None and not given and not rest:
        if args.retries is None:
            return None
        if not manifest.is_file():
            raise FileNotFoundError(
                f"{root} is not a sweep directory (no {MANIFEST_FILE}): --retries alone "
                "changes an existing sweep; give --spec FILE or the axis flags for a new one"
            )
        return dataclasses.replace(open_sweep(root).spec, retries=args.retries)
    raw: dict[str, Any] = read_settings_file(args.spec) if args.spec else {}
    spec = SweepSpec.from_dict(raw, args.spec or "the command line")
    # A flag changes its one field of a part (--td3-tau), not the spec file's whole part.
    command = args.sweep_command
    config = merge_settings(spec.config, _train_settings(rest, command)) if rest else spec.config
    changes: dict[str, Any] = {**given, "config": dict(config)}
    if args.retries is not None:
        changes["retries"] = args.retries
    elif "retries" not in raw and manifest.is_file():  # the sweep there keeps its own
        changes["retries"] = open_sweep(root).spec.retries
    return SweepSpec(**{**spec.to_dict(), **changes})


def _run_sweep(args: argparse.Namespace) -> int:
    from ilfo.experiments import progress_line, record_attempt, run_sweeps

    _check_flags_follow_dirs(args)
    roots = [Path(d) for d in args.dir]
    make_backend = _backend_factory(args)  # bad --workers or --cores-per-run fail before all
    if len(roots) == 1:
        plan = _one_sweep(args, roots[0])
    else:
        plan = _several_sweeps(args, roots)
    if plan is None:  # a dry run: listed
        return 0
    sweeps, chosen = plan
    backend = make_backend()  # before failures are forgotten: a missing Ray forgets none
    if args.retry_failed:
        for sweep, names in zip(sweeps, chosen, strict=True):
            for status in sweep.statuses():
                if status.state == "failed" and status.name in names:
                    record_attempt(sweep, status.name, "reset")
    at_once = f"{backend.slots} at once ({args.backend})"
    for sweep, names in zip(sweeps, chosen, strict=True):
        print(
            f"sweep {sweep.root}: {_count(len(sweep.runs), 'run')}"
            + (f", {at_once}" if len(sweeps) == 1 else "")
        )
        if len(names) < len(sweep.runs):
            left = len(sweep.runs) - len(names)
            print(
                f"running {len(names)} of them (--only/--skip); the other {left} "
                f"{'is' if left == 1 else 'are'} left as they are"
            )
    if len(sweeps) > 1:
        print(f"{sum(len(s.runs) for s in sweeps)} runs in {len(sweeps)} sweeps, {at_once}")
    statuses = [status for sweep in sweeps for status in sweep.statuses()]
    print(progress_line(statuses))
    display = _Progress(statuses, enabled=not args.no_progress)
    try:
        with stop_signals_interrupt():
            final = run_sweeps(sweeps, backend, on_change=display.update, names=chosen)
    finally:
        display.close()
    print(progress_line(final))
    start = 0
    for sweep in sweeps:  # `final` holds each sweep's runs in turn
        mine = final[start : start + len(sweep.runs)]
        start += len(sweep.runs)
        _print_failed(sweep, [s for s in mine if s.state == "failed"])
        for status in mine:
            if status.state == "unresumable":
                print(f"unresumable: {status.name}: {status.error}")
    return 1 if any(s.state == "failed" for s in final) else 0


_SweepPlan = tuple[list[Any], list[tuple[str, ...]]]  # the sweeps, and each one's runs to run


def _one_sweep(args: argparse.Namespace, root: Path) -> _SweepPlan | None:
    """The sweep in (or for) ``root``, created from the spec or axes given, and its chosen
    runs; ``None`` after a dry run's listing."""
    from ilfo.experiments import create_sweep, expand, matching_sweep, open_sweep, select_runs

    spec = _spec_from_args(args, root, list(args.rest))
    # An existing sweep given a spec must be the same sweep, --dry-run or not.
    sweep = open_sweep(root) if spec is None else matching_sweep(root, spec)
    runs = sweep.runs if sweep is not None else expand(spec)
    # Chosen before a new sweep directory is made: a misspelt pattern leaves nothing behind.
    chosen = select_runs([run.name for run in runs], args.only, args.skip)
    if args.dry_run:
        if sweep is None:
            for run in runs:
                print(run.name if run.name in chosen else f"{run.name}  (left out)")
        else:
            _list_runs(sweep, chosen, prefix="")
        return None
    if spec is not None:  # a new sweep, or the same one with other retries
        sweep = create_sweep(root, spec)
    assert sweep is not None
    return [sweep], [chosen]


def _run_sweep_create(args: argparse.Namespace) -> int:
    import shlex

    from ilfo.experiments import create_sweep, matching_sweep
    from ilfo.experiments.sweep import MANIFEST_FILE

    _check_flags_follow_dirs(args)
    root = Path(args.dir)
    spec = _spec_from_args(args, root, list(args.rest))
    if spec is None:
        holds_sweep = (root / MANIFEST_FILE).is_file()
        raise ValueError(
            "nothing to create: give --spec FILE, the axis flags (--env, --algo, --num-demos, "
            "--seeds) or `ilfo train` flags (the axes' defaults apply)"
            + (f"; {root} holds a sweep already: ilfo sweep status {root}" if holds_sweep else "")
        )
    before = matching_sweep(root, spec)  # another sweep there is refused
    sweep = create_sweep(root, spec)
    there = ""
    if before is not None:
        retries = before.spec.retries
        there = " (there already" + (
            f"; retries {retries} -> {spec.retries})" if retries != spec.retries else ")"
        )
    print(f"sweep {root}: {_count(len(sweep.runs), 'run')}{there}")
    _list_runs(sweep, tuple(run.name for run in sweep.runs), prefix="")
    where = shlex.quote(str(root))
    print(f"run it: ilfo sweep run {where}; or queue it: ilfo sweep run OTHER... {where}")
    return 0


def _several_sweeps(args: argparse.Namespace, roots: list[Path]) -> _SweepPlan | None:
    """Existing sweeps to continue as one queue, and each one's chosen runs (--only and --skip
    apply to all: a pattern must match a run of one of them); ``None`` after a dry run's
    listing."""
    from ilfo.experiments import select_runs, sweep_labels

    changes = [
        flag
        for flag, value in (
            ("--spec", args.spec),
            ("--env", args.env),
            ("--algo", args.algo),
            ("--num-demos", args.num_demos),
            ("--seeds", args.seeds),
            ("--retries", args.retries),
        )
        if value is not None
    ]
    if args.rest:
        changes.append(f"ilfo train flags ({' '.join(args.rest)})")
    if changes:
        raise ValueError(
            f"several sweep directories are continued as they are; {', '.join(changes)} "
            "make or change one sweep: give one DIR"
        )
    sweeps = _open_sweeps(roots)
    selected = set(select_runs([r.name for s in sweeps for r in s.runs], args.only, args.skip))
    chosen = [tuple(r.name for r in s.runs if r.name in selected) for s in sweeps]
    if args.dry_run:
        for sweep, names, label in zip(sweeps, chosen, sweep_labels(sweeps), strict=True):
            _list_runs(sweep, names, prefix=f"{label}/")
        return None
    return sweeps, chosen


def _open_sweeps(roots: list[Path]) -> list[Any]:
    if len({root.resolve() for root in roots}) < len(roots):
        raise ValueError(f"a sweep directory is given twice: {' '.join(map(str, roots))}")
    from ilfo.experiments import open_sweep

    return [open_sweep(root) for root in roots]


def _list_runs(sweep: Any, chosen: tuple[str, ...], prefix: str) -> None:
    for status in sweep.statuses():
        left_out = "" if status.name in chosen else "  (left out)"
        print(f"{prefix}{status.name}  {status.state}{left_out}")


def _print_failed(sweep: Any, failed: list[Any]) -> None:
    """A line per run given up after its retries: its last error and its log."""
    for status in failed:
        print(f"failed: {status.name}: {status.error} (log: {sweep.log_file(status.name)})")


class _Progress:
    """A bar over the whole sweep's steps, with the counts by state; events as lines."""

    def __init__(self, statuses: list[Any], enabled: bool) -> None:
        from tqdm import tqdm

        from ilfo.experiments import summary

        counts = summary(statuses)
        self._bar = tqdm(
            total=counts["steps_total"],
            initial=counts["steps_done"],
            unit="step",
            disable=not enabled,
            file=sys.stderr,
        )

    def update(self, statuses: list[Any], message: str) -> None:
        from ilfo.experiments import summary

        counts = summary(statuses)
        self._bar.total = counts["steps_total"]
        self._bar.n = counts["steps_done"]
        unresumable = f" unresumable {counts['unresumable']}" if counts["unresumable"] else ""
        self._bar.set_postfix_str(
            f"done {counts['done']} running {counts['running']} failed {counts['failed']} "
            f"pending {counts['pending']}{unresumable}",
            refresh=True,
        )
        if message:
            self._bar.write(message)

    def write(self, line: str) -> None:
        """A line above the bar (printed whether or not the bar is shown)."""
        self._bar.write(line)

    def close(self) -> None:
        self._bar.close()


def _run_sweep_status(args: argparse.Namespace) -> int:
    from ilfo.experiments import progress_line, summary, sweep_labels

    sweeps = _open_sweeps([Path(d) for d in args.dir])
    several = len(sweeps) > 1
    rows = [  # (the name shown, the status, the sweep's directory)
        (f"{label}/{s.name}" if several else s.name, s, sweep.root)
        for sweep, label in zip(sweeps, sweep_labels(sweeps), strict=True)
        for s in sweep.statuses()
    ]
    if args.json:
        for _, status, root in rows:
            print(
                json.dumps({"sweep": str(root), **status.__dict__, "hours_left": status.hours_left})
            )
        return 0
    width = max(len(name) for name, _, _ in rows)
    state_width = max(len("pending"), *(len(s.state) for _, s, _ in rows))
    for name, s, _ in rows:
        error = f"  {s.error}" if s.error and s.state != "done" else ""
        failures = f"  failures {s.failures}" if s.failures else ""
        speed = (
            f"  {s.steps_per_s:,.0f} steps/s, ~{s.hours_left:.1f} h left"
            if s.hours_left is not None
            else ""
        )
        print(
            f"{name:<{width}}  {s.state:<{state_width}}  {s.step:>9,}/{s.steps:,}{speed}"
            f"{failures}{error}"
        )
    statuses = [s for _, s, _ in rows]
    counts = summary(statuses)
    share = counts["steps_done"] / max(1, counts["steps_total"])
    bar = "#" * round(30 * share)
    print(f"[{bar:<30}] {progress_line(statuses)}")
    return 0


def _run_sweep_snapshot(args: argparse.Namespace) -> int:
    from ilfo.experiments import snapshot_sweep

    kept = snapshot_sweep(args.dir, args.out)
    width = max(len(name) for name in kept)
    for name, what in kept.items():
        print(f"{name:<{width}}  {what}")
    print(f"wrote {args.out}; continue it with `ilfo sweep run {args.out}`")
    return 0


def _add_backend_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--backend", choices=["local", "ray"], default="local")
    p.add_argument(
        "--cores-per-run",
        type=int,
        default=1,
        help="CPUs (and BLAS/XLA threads) of each run (default 1: one run per core)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="runs at once (default: cores / --cores-per-run); with --backend ray, the size "
        "of a local Ray instance",
    )
    p.add_argument(
        "--address",
        default=None,
        help="Ray backend: the cluster ('auto' or HOST:PORT); default: a local Ray instance",
    )


def _backend_factory(args: argparse.Namespace) -> Any:
    """A function making the backend the flags ask for (checked now, made when the runs start)."""
    from ilfo.experiments import LocalBackend, RayBackend

    if args.backend == "ray":
        if args.cores_per_run < 1:  # before any sweep directory is made
            raise ValueError(f"--cores-per-run must be >= 1, got {args.cores_per_run}")
        if args.workers is not None and (args.workers < 1 or args.address is not None):
            raise ValueError(
                "--workers with --backend ray sizes a local Ray instance (>= 1); a cluster "
                "(--address) runs as many as its CPUs hold"
            )
        num_cpus = None if args.workers is None else args.workers * args.cores_per_run
        return lambda: RayBackend(args.address, cores_per_run=args.cores_per_run, num_cpus=num_cpus)
    if args.address is not None:
        raise ValueError("--address is for --backend ray")
    LocalBackend(args.cores_per_run, args.workers)  # bad numbers fail before any run starts
    return lambda: LocalBackend(args.cores_per_run, args.workers)


def _add_reproduce_parser(sub: argparse._SubParsersAction) -> None:
    from ilfo.experiments.reproduce import BUDGETS, EXPERIMENTS

    p = sub.add_parser(
        "reproduce",
        help="Run one of the paper's experiments (tables) at a budget, and report on it.",
        description=(
            "Run the sweeps of one of the paper's experiments and write the report beside the "
            "paper's numbers. Budgets: smoke (minutes, tiny runs: proves the pipeline), small "
            "(about a day on 2 cores: fewer tasks, seeds and steps), full (the paper's "
            "protocol). Prints the plan and its estimated core-hours first; resumable: run the "
            "same command again to continue."
        ),
    )
    p.add_argument("name", choices=list(EXPERIMENTS), help="the experiment")
    p.add_argument("--budget", choices=list(BUDGETS), default="smoke")
    p.add_argument(
        "--dir", default=None, help="where its sweeps and report go (default reproduce/NAME-BUDGET)"
    )
    _add_backend_arguments(p)
    p.add_argument("--dry-run", action="store_true", help="print the plan and stop")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_reproduce)


def _run_reproduce(args: argparse.Namespace) -> int:
    from ilfo.experiments import open_sweep
    from ilfo.experiments.reproduce import plan, reproduce

    the_plan = plan(args.name, args.budget)
    root = Path(args.dir or f"reproduce/{args.name}-{args.budget}")
    print(the_plan.describe(root))
    if args.dry_run:
        return 0
    factory = _backend_factory(args)
    display = _Progress([], enabled=not args.no_progress)
    try:
        with stop_signals_interrupt():
            _, written = reproduce(
                args.name, args.budget, root, factory, on_change=display.update, log=display.write
            )
    finally:
        display.close()
    print(f"report: {written[0]}")
    # Runs given up after their retries are left out of the report: the command failed.
    failed = False
    for sub in the_plan.sweeps:
        sweep = open_sweep(root / sub)
        given_up = [s for s in sweep.statuses() if s.state == "failed"]
        _print_failed(sweep, given_up)
        failed = failed or bool(given_up)
    if failed:
        print(
            "retry them with `ilfo sweep run DIR --retry-failed` on their sweep directories, "
            "then run this command again for the report"
        )
    return 1 if failed else 0
