"""What the bench/ scripts share: a one-line description of the machine they ran on."""

from __future__ import annotations

import os
import platform

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
