"""``ilfo diagnose``: why a run's imitation does (not) learn (``ilfo.diagnose``)."""

from __future__ import annotations

import argparse
from pathlib import Path


def _add_diagnose_parser(sub: argparse._SubParsersAction) -> None:
    from ilfo.training.config import MAX_EVAL_EPISODES

    p = sub.add_parser(
        "diagnose",
        help="Diagnose an imitation run: where its OT distance goes, its reward per step.",
        description=(
            "Roll out an imitation run's final policy (policy.msgpack, or its last "
            "checkpoint's) in deterministic fixed-horizon episodes and compare them with the "
            "demos it imitates as OOPS does: each state dimension's share of the transported "
            "cost, the proxy reward beside the task reward per step, the learner's OT distance "
            "among noisy copies of the demonstrator, and the learner's and the demo's "
            "trajectories in the dimensions that cost most. Writes diagnosis.md and PNG "
            "figures to --out (default RUN_DIR/diagnosis/) and prints a summary."
        ),
    )
    p.add_argument("run_dir", help="a run directory written by `ilfo train` (an imitation run)")
    p.add_argument(
        "--demos",
        metavar="FILE",
        default=None,
        help="compare with this demo file (its first episodes, as many as the run imitates) "
        "instead of the run's demos",
    )
    p.add_argument(
        "--out", metavar="DIR", default=None, help="report directory (default RUN_DIR/diagnosis)"
    )
    p.add_argument(
        "--episodes",
        type=int,
        default=1,
        metavar="N",
        help=f"episodes to roll out, on the run's evaluation seeds (default 1, at most "
        f"{MAX_EVAL_EPISODES:,})",
    )
    p.add_argument(
        "--best", action="store_true", help="diagnose best_policy.msgpack instead of the final one"
    )
    p.set_defaults(run=_run_diagnose)


def _run_diagnose(args: argparse.Namespace) -> int:
    from ilfo.diagnose import diagnose_run, summary_lines, write_report

    run_dir = Path(args.run_dir)
    result = diagnose_run(run_dir, demos=args.demos, episodes=args.episodes, best=args.best)
    written = write_report(result, Path(args.out) if args.out else run_dir / "diagnosis")
    print("\n".join(summary_lines(result, written[0])))
    return 0
