"""What the commands share: the parser, how to tell the user to start ``ilfo`` again, and how
a long command is stopped."""

from __future__ import annotations

import argparse
import contextlib
import os
import shlex
import shutil
import signal
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

USAGE_LINES_SHOWN_WITH_AN_ERROR = 6
"""A longer usage (``ilfo train``'s is 100+ lines) is replaced by a pointer to ``--help``."""


class Parser(argparse.ArgumentParser):
    """argparse's parser, except that a bad argument is not buried under a long usage.

    ``help_command``: the command whose ``--help`` lists the options (default: this parser's
    prog), for a parser whose prog is not a command of its own."""

    help_command: str | None = None

    def error(self, message: str) -> NoReturn:
        usage = self.format_usage()
        # A usage given in words ("[options]": ``ilfo train``'s) says where the options are too.
        if self.usage is not None or usage.count("\n") > USAGE_LINES_SHOWN_WITH_AN_ERROR:
            command = self.help_command or self.prog
            usage = f"usage: {self.prog} [options]  (all of them: {command} --help)\n"
        sys.stderr.write(usage)
        self.exit(2, f"{self.prog}: error: {message}\n")


def check_jax_platforms() -> None:
    """A ValueError saying what to do where ``JAX_PLATFORMS`` names an accelerator this JAX
    cannot start (without a CUDA build of JAX, ``JAX_PLATFORMS=cuda`` ends in a bare
    AssertionError deep inside JAX at the first array)."""
    wanted = [p.strip() for p in os.environ.get("JAX_PLATFORMS", "").split(",") if p.strip()]
    accelerators = [p for p in wanted if p != "cpu"]
    if not accelerators:
        return
    import jax  # only here: most commands import it anyway, and only this check needs it now

    for platform in accelerators:
        try:
            jax.devices(platform)
        except (RuntimeError, AssertionError) as err:
            detail = str(err).split("\n")[0] or type(err).__name__
            raise ValueError(
                f"JAX_PLATFORMS={os.environ['JAX_PLATFORMS']}: JAX cannot start {platform!r} "
                f"here ({detail}). For an NVIDIA GPU install a CUDA build of JAX (pip install "
                "'jax[cuda12]', the same version as ilfo's jax); to run on the CPU, unset "
                "JAX_PLATFORMS. ilfo's GPU runs are untested."
            ) from None


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


@contextlib.contextmanager
def stop_signals_interrupt() -> Iterator[None]:
    """Within it, SIGINT and SIGTERM raise KeyboardInterrupt, the path on which a sweep asks
    its runs to checkpoint and waits for them: SIGINT even where the process started with it
    ignored (a job put in the background by a non-interactive shell, ``nohup cmd &`` in a
    script), and ``kill PID`` as well as Ctrl-C. Outside the main thread, nothing changes."""

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.getsignal(sig)
            signal.signal(sig, interrupt)
    except ValueError:  # not the main thread
        pass
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
