"""What the bench/ scripts share: a one-line description of the machine they ran on, and how
they print their rows."""

from __future__ import annotations

import argparse
import json
import os
import platform
from collections.abc import Mapping, Sequence
from datetime import date
from typing import Any

import numpy as np


def machine(**versions: str) -> str:
    """CPU model, cores, Python and numpy versions, then ``name version`` for each keyword."""
    model = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            model = next(
                (line.split(":", 1)[1].strip() for line in f if line.startswith("model name")),
                model,
            )
    except OSError:
        pass
    extra = "".join(f", {name} {version}" for name, version in versions.items())
    python = platform.python_version()
    return f"{model}, {os.cpu_count()} cores, Python {python}, numpy {np.__version__}{extra}"


def print_rows(
    rows: Sequence[Mapping[str, Any]], columns: Mapping[str, str], as_json: bool
) -> None:
    """Print a benchmark's rows: as JSON lines, each with the date and ``machine()``, or as a
    markdown table under a line naming both. ``columns`` maps each header to a format string
    of the row's fields (``{"ms per solve": "{ms:.1f}"}``)."""
    today = date.today().isoformat()
    if as_json:
        for row in rows:
            print(json.dumps({**row, "date": today, "machine": machine()}))
        return
    print(f"{today}, {machine()}")
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for row in rows:
        print("| " + " | ".join(fmt.format(**row) for fmt in columns.values()) + " |")


def parse_policy_arguments(parser: argparse.ArgumentParser, first_seed: int) -> argparse.Namespace:
    """Parse the arguments of a bench script that rolls out one policy: a run directory (its
    final policy, or ``--best``) or ``--expert`` (an exported expert), exactly one of them, on
    ``--episodes`` seeds from ``--first-seed``, printed as a table or ``--json`` lines."""
    parser.add_argument("run_dir", nargs="?", help="an `ilfo train` or `ilfo expert train` run")
    parser.add_argument("--expert", default=None, help="an exported expert (env id or directory)")
    parser.add_argument("--best", action="store_true", help="the run's best policy, not its last")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=first_seed)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if (args.run_dir is None) == (args.expert is None):
        parser.error("give a run directory or --expert, not both")
    return args
