"""The ``ilfo`` command line: thin wrappers over the library, one module per command group
(``train``: train, eval, plot, snapshot; ``diagnose``; ``experts``: expert train / export /
eval; ``data``: reward, demos info / convert / collect, label; ``experiments``: sweep run /
create / status / snapshot, reproduce; ``report``)."""

from __future__ import annotations

import sys
import warnings
from collections.abc import Sequence
from typing import TextIO

from ilfo.cli._common import Parser, check_jax_platforms
from ilfo.cli._common import _command as _command  # re-exported: ilfo.cli._command
from ilfo.cli.data import _add_demos_parser, _add_label_parser, _add_reward_parser
from ilfo.cli.diagnose import _add_diagnose_parser
from ilfo.cli.experiments import _add_reproduce_parser, _add_sweep_parser
from ilfo.cli.experts import _add_expert_parser
from ilfo.cli.report import _add_report_parser
from ilfo.cli.train import (
    _add_eval_parser,
    _add_plot_parser,
    _add_snapshot_parser,
    _add_train_parser,
)
from ilfo.compilation_cache import enable_compilation_cache

__all__ = ["build_parser", "main"]


def build_parser() -> Parser:
    """The ``ilfo`` command's parser, with every subcommand's (docs/cli.md is generated from
    it: ``python scripts/gen_cli_reference.py``)."""
    parser = Parser(  # its subcommands' parsers are of its class
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
    _add_snapshot_parser(sub)
    _add_diagnose_parser(sub)
    _add_expert_parser(sub)
    _add_reward_parser(sub)
    _add_demos_parser(sub)
    _add_label_parser(sub)
    _add_sweep_parser(sub)
    _add_report_parser(sub)
    _add_reproduce_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ilfo`` console script."""
    parser = build_parser()
    args, rest = parser.parse_known_args(argv)
    if rest and not getattr(args, "takes_train_flags", False):
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    args.rest = rest  # `ilfo sweep run`: the `ilfo train` flags of every run
    try:
        with warnings.catch_warnings():  # restores the default display on the way out
            warnings.showwarning = _show_warning
            check_jax_platforms()
            enable_compilation_cache()  # before the first compilation; see its module
            return args.run(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"ilfo: error: {err}", file=sys.stderr)
        return 2
    except ImportError as err:  # an optional dependency missing (PyBullet, h5py, Ray, ...)
        print(f"ilfo: error: {err}", file=sys.stderr)
        return 1
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
