"""``ilfo report``."""

from __future__ import annotations

import argparse
import sys


def _add_report_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="Tables and figures over runs: final scores, IQM with bootstrap CIs, the paper's.",
        description=(
            "Report on runs (sweep directories, run directories, or folders holding them): per "
            "task x algo x demos (x variant), the paper's final performance (the last "
            "evaluation's normalised score, mean +- std over seeds) beside the IQM with a 95% "
            "stratified-bootstrap interval and the paper's number (flagged when outside its "
            "+- 2 std); aggregates over tasks, probability of improvement, learning curves and "
            "performance profiles. Writes report.md, cells.csv, aggregates.csv, "
            "improvement.csv and PNG figures."
        ),
    )
    p.add_argument("paths", nargs="+", help="sweep or run directories (searched recursively)")
    p.add_argument("--out", default="report", help="output directory (default: report)")
    p.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples (default 2000)")
    p.set_defaults(run=_run_report)


def _run_report(args: argparse.Namespace) -> int:
    from ilfo.experiments.report import build_report, collect_runs
    from ilfo.experiments.report_tables import write_report

    if args.resamples < 100:
        raise ValueError(f"--resamples must be >= 100, got {args.resamples}")
    runs, skipped = collect_runs(args.paths)
    for line in skipped:
        print(f"left out: {line}", file=sys.stderr)
    if not runs:
        raise ValueError(f"no run with an evaluation under {', '.join(args.paths)}")
    report = build_report(runs, skipped=skipped, resamples=args.resamples)
    written = write_report(report, args.out, sources=args.paths)
    print(f"{len(runs)} runs, {len(report.cells)} cells; wrote {', '.join(map(str, written))}")
    return 0
