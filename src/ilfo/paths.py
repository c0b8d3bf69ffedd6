"""Where ilfo's shipped data lives."""

from __future__ import annotations

from pathlib import Path

# The repository's data/ folder (ilfo is installed from a checkout, `pip install -e .`).
DATA_DIR = Path(__file__).resolve().parents[2] / "data"


def bundled_demos(name: str) -> Path:
    """Path of a shipped demonstration file under data/demos/, e.g. ``Hopper-v5-scripted``."""
    path = DATA_DIR / "demos" / f"{name}.npz"
    if not path.is_file():
        available = sorted(p.stem for p in (DATA_DIR / "demos").glob("*.npz"))
        raise FileNotFoundError(
            f"no bundled demos named {name!r} in {path.parent}; available: {available or 'none'}"
        )
    return path


def default_demos_path(env_id: str) -> Path:
    """The shipped expert demos of ``env_id``, data/experts/<env_id>/demos.npz: what
    ``ilfo train --env ENV`` imitates without ``--demos`` (the file may not exist: not every env
    has a shipped expert)."""
    return DATA_DIR / "experts" / env_id / "demos.npz"
