"""Demonstration data: ilfo's own npz format (schema-versioned, no pickle) and offline readers
for Minari, D4RL and imitation-library files (``load_any``)."""

from ilfo.demos.npz import DemoFile, Episode, load, save
from ilfo.demos.readers import (
    FORMATS,
    detect_format,
    load_any,
    read_d4rl,
    read_ilfo,
    read_imitation,
    read_minari,
    summarize,
)

__all__ = [
    "FORMATS",
    "DemoFile",
    "Episode",
    "detect_format",
    "load",
    "load_any",
    "read_d4rl",
    "read_ilfo",
    "read_imitation",
    "read_minari",
    "save",
    "summarize",
]
