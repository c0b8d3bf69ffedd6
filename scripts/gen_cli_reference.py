"""Write docs/cli.md, the command-line reference, from ilfo's argparse parsers: every command's
and subcommand's ``--help``, as argparse prints it at 100 columns.

    python scripts/gen_cli_reference.py          # rewrite docs/cli.md
    python scripts/gen_cli_reference.py --check  # exit 1 where docs/cli.md is out of date

tests/test_docs.py fails when the committed page differs from what this writes.
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Iterator
from pathlib import Path

from ilfo.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "cli.md"
COMMAND = "python scripts/gen_cli_reference.py"
WIDTH = 100  # argparse wraps help at the terminal's width: fixed, so the page is the same anywhere

HEADER = f"""# Command-line reference

Every `ilfo` command's `--help`, generated from the parsers by
`{COMMAND}`: do not edit by hand (a test fails when this page and
the parsers differ). How the commands are used: [the guide](guide.md#the-command-line) and
[experiments](experiments.md).
"""


def commands(parser: argparse.ArgumentParser) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """``(prog, parser)`` for ``parser`` and each of its subcommands, depth first, in the order
    they were added."""
    yield parser.prog, parser
    for action in parser._actions:  # argparse keeps its subcommands only here
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):  # aliases share a parser
                yield from commands(sub)


def reference() -> str:
    """The text of docs/cli.md."""
    sections = [HEADER]
    for prog, parser in commands(build_parser()):
        # Without a width, argparse's formatter takes the terminal's.
        parser.formatter_class = functools.partial(parser.formatter_class, width=WIDTH)
        depth = min(prog.count(" ") + 1, 3)  # ilfo: ##, ilfo train: ##, ilfo sweep run: ###
        heading = "#" * max(depth, 2)
        sections.append(f"{heading} `{prog}`\n\n```text\n{parser.format_help().rstrip()}\n```\n")
    return "\n".join(sections)


def main() -> int:
    check = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    check.add_argument("--check", action="store_true", help="only compare, write nothing")
    text = reference()
    if check.parse_args().check:
        current = PAGE.read_text() if PAGE.exists() else ""
        if current != text:
            print(f"{PAGE.relative_to(ROOT)} is out of date: run {COMMAND}", file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(text)
    print(f"wrote {PAGE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
