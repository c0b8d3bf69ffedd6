"""ilfo's demonstration file: one ``.npz`` archive, read with ``allow_pickle=False``.

Layout (schema 1): ``schema_version`` (int), ``env_id`` (str), ``provenance`` (JSON str),
``episode_lengths`` (N,) number of observations of each episode (T_i + 1), ``observations``
(sum_i (T_i + 1), obs_dim) all episodes end to end, and optionally ``actions``, ``rewards`` and
``terminated`` (sum_i T_i, ...) kept for analysis only: a learner never sees them.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

SCHEMA_VERSION = 1


@dataclass(frozen=True)
class Episode:
    """One demonstration.

    Attributes:
        observations: Shape (T + 1, obs_dim).
        actions: Shape (T, act_dim), or None. Analysis only.
        rewards: Shape (T,), or None. Analysis only.
        terminated: Shape (T,) bool, or None: the steps on which the environment reported
            termination, in a fixed-horizon episode that went on past it. Analysis only.
    """

    observations: np.ndarray
    actions: np.ndarray | None = None
    rewards: np.ndarray | None = None
    terminated: np.ndarray | None = None

    @property
    def task_return(self) -> float | None:
        """Sum of the recorded task rewards, or None where none were recorded."""
        return None if self.rewards is None else float(self.rewards.sum())

    @property
    def task_score(self) -> float | None:
        """The paper's fixed-horizon score: the task rewards summed with those of steps on which
        the environment reported termination counted as 0 (what ``ilfo train`` evaluates and
        divides by the demos' mean). Equal to ``task_return`` where no termination was
        recorded; None where no rewards were."""
        if self.rewards is None or self.terminated is None:
            return self.task_return
        return float(np.where(self.terminated, 0.0, self.rewards).sum())


@dataclass(frozen=True)
class DemoFile:
    """The contents of a demonstration file."""

    episodes: list[Episode]
    env_id: str
    provenance: dict[str, Any] = field(default_factory=dict)


def save(
    path: str | Path,
    episodes: Sequence[Episode],
    env_id: str,
    provenance: dict[str, Any] | None = None,
) -> None:
    """Write episodes to ``path`` (.npz) in schema 1."""
    if not episodes:
        raise ValueError("no episodes to save")
    lengths = np.array([len(e.observations) for e in episodes], dtype=np.int64)
    arrays: dict[str, np.ndarray] = {
        "schema_version": np.array(SCHEMA_VERSION),
        "env_id": np.array(env_id),
        "provenance": np.array(json.dumps(provenance or {}, sort_keys=True)),
        "episode_lengths": lengths,
        "observations": np.concatenate([e.observations for e in episodes]),
    }
    for name in ("actions", "rewards", "terminated"):
        parts = [getattr(e, name) for e in episodes]
        if all(p is not None for p in parts):
            arrays[name] = np.concatenate(parts)
    np.savez_compressed(path, **arrays)


def load(path: str | Path) -> DemoFile:
    """Read a schema-1 file; raise ValueError naming the problem for a bad one."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no demonstration file at {path}")
    try:
        with np.load(path, allow_pickle=False) as archive:
            data = {k: archive[k] for k in archive.files}
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, TypeError) as err:
        raise ValueError(f"{path} is not a readable .npz archive ({err})") from None
    for key in ("schema_version", "episode_lengths", "observations"):
        if key not in data:
            raise ValueError(f"{path} lacks the key {key!r}: not an ilfo demonstration file")
    if int(data["schema_version"]) != SCHEMA_VERSION:
        raise ValueError(f"{path} has schema {int(data['schema_version'])}, expected 1")
    lengths = data["episode_lengths"].astype(np.int64)
    obs = data["observations"]
    if obs.ndim != 2 or lengths.ndim != 1 or (lengths < 2).any() or lengths.sum() != len(obs):
        raise ValueError(f"{path}: observations {obs.shape} do not match episode_lengths")
    if not np.isfinite(obs).all():
        raise ValueError(f"{path}: observations contain NaN or inf")
    bounds = np.concatenate([[0], np.cumsum(lengths)])
    step_bounds = np.concatenate([[0], np.cumsum(lengths - 1)])
    extras = {}
    for name in ("actions", "rewards", "terminated"):
        if name in data:
            if len(data[name]) != step_bounds[-1]:
                raise ValueError(
                    f"{path}: {name} has {len(data[name])} rows, not {step_bounds[-1]}"
                )
            if name == "terminated" and data[name].dtype != np.bool_:
                raise ValueError(f"{path}: terminated must be boolean, not {data[name].dtype}")
            extras[name] = data[name]
    episodes = [
        Episode(
            observations=obs[bounds[i] : bounds[i + 1]],
            **{k: v[step_bounds[i] : step_bounds[i + 1]] for k, v in extras.items()},
        )
        for i in range(len(lengths))
    ]
    provenance = json.loads(str(data["provenance"])) if "provenance" in data else {}
    env_id = str(data["env_id"]) if "env_id" in data else ""
    return DemoFile(episodes=episodes, env_id=env_id, provenance=provenance)
