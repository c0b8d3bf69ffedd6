"""What the commands share: how to tell the user to start ``ilfo`` again."""

from __future__ import annotations

import shlex
import shutil
import sys
from pathlib import Path


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
