"""What the commands share: how to tell the user to start ``ilfo`` again, and how a long
command is stopped."""

from __future__ import annotations

import contextlib
import shlex
import shutil
import signal
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any


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
