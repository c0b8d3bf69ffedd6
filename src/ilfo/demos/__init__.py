"""Demonstration data: ilfo's own npz format (schema-versioned, no pickle)."""

from ilfo.demos.npz import Episode, load, save

__all__ = ["Episode", "load", "save"]
