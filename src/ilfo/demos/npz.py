"""ilfo's demonstration file: one ``.npz`` archive, read with ``allow_pickle=False``.

Layout (schema 1): ``schema_version`` (int), ``env_id`` (str), ``provenance`` (JSON str),
``episode_lengths`` (N,) number of observations of each episode (T_i + 1), ``observations``
(sum_i (T_i + 1), obs_dim) all episodes end to end, and optionally ``actions``, ``rewards`` and
``terminated`` (sum_i T_i, ...) kept for analysis only: a learner never sees them.

Observations and actions are written as float32 where that moves no value by more than
``FLOAT32_TOLERANCE`` of its column's standard deviation (``float32_is_lossless``), float64
otherwise; rewards always as float64 (scores are sums of them). Readers accept either.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ilfo.npz_check import check_npz

SCHEMA_VERSION = 1

FLOAT32_TOLERANCE = 1e-4
"""The largest float32 rounding error ``save`` accepts, as a fraction of the column's standard
deviation over the file (of 1 for a constant column). Every reward in ilfo compares standardised
states, whose scale is at least that standard deviation (OOPS's at least 3 x 0.33), so the
rounding moves a standardised coordinate by at most 1e-4: far below the differences a reward
grades (Sinkhorn's lambda is 0.05 in cost units)."""


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
    compact: bool = True,
) -> None:
    """Write episodes to ``path`` (.npz) in schema 1, checked as ``load`` checks them (so what
    is written can be read back), and atomically: a crash part-way leaves any old file whole.

    ``compact``: observations and actions as float32 where ``float32_is_lossless`` (half the
    size); False keeps their float dtypes (integer observations are written as float64, as
    ``load`` would read them; 1-D actions as (T, 1)). Actions, rewards and terminated are kept where
    every episode has them; a ValueError where only some do (they would be lost).
    """
    path = Path(path)
    if path.suffix != ".npz":  # numpy would append one and write elsewhere
        raise ValueError(f"{path}: a demonstration file's name ends in .npz")
    if not isinstance(env_id, str):
        raise ValueError(f"env_id must be a string (a gymnasium id, or ''), got {env_id!r}")
    if not episodes:
        raise ValueError("no episodes to save")
    episodes = checked_episodes(list(episodes), f"{path} (not written)")
    for name in ("actions", "rewards", "terminated"):
        have = [getattr(e, name) is not None for e in episodes]
        if any(have) and not all(have):
            raise ValueError(
                f"{path} (not written): episodes {_indices(have)} have {name}, episodes "
                f"{_indices([not h for h in have])} none; give them to all episodes or to none"
            )
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
    if compact:
        for name in ("observations", "actions"):
            if name in arrays and float32_is_lossless(arrays[name]):
                arrays[name] = arrays[name].astype(np.float32)
    target = path.resolve()  # through a symlink to its file, as numpy wrote
    if not target.parent.is_dir():  # else the error would name the temporary file
        raise FileNotFoundError(f"{path} (not written): its folder {target.parent} does not exist")
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")  # one per writing process
    try:
        with open(tmp, "wb") as file:  # a file object: numpy adds no suffix
            # numpy's stubs let **arrays fill allow_pickle (a bool); these keys are array names.
            np.savez_compressed(file, **arrays)  # type: ignore[arg-type]
        os.replace(tmp, target)
    except OSError as err:  # a full disk: the message names the file (ilfo.cli prints it)
        if err.filename is not None:
            raise
        raise OSError(err.errno, err.strerror or str(err), str(path)) from err
    finally:
        tmp.unlink(missing_ok=True)


def _indices(flags: list[bool], shown: int = 5) -> str:
    """'0, 2, 7' for the True entries, the first ``shown`` of them and a count of the rest."""
    hits = [str(i) for i, flag in enumerate(flags) if flag]
    more = f" and {len(hits) - shown} more" if len(hits) > shown else ""
    return ", ".join(hits[:shown]) + more


def float32_is_lossless(values: np.ndarray, tolerance: float = FLOAT32_TOLERANCE) -> bool:
    """Whether float32 rounds no value of ``values`` (rows, columns) by more than ``tolerance``
    of its column's standard deviation (of 1 where the column is constant), and keeps every
    value finite. True for float32 input; False for non-float or 1-D input."""
    values = np.asarray(values)
    if values.dtype.kind != "f" or values.ndim != 2 or values.size == 0:
        return False
    if values.dtype.itemsize <= 4:
        return True
    with np.errstate(over="ignore"):
        rounded = values.astype(np.float32)
    if not np.isfinite(rounded).all():
        return False
    error = np.abs(rounded.astype(np.float64) - values).max(axis=0)
    constant = values.max(axis=0) == values.min(axis=0)
    scale = np.where(constant, 1.0, values.std(axis=0))
    return bool((error <= tolerance * scale).all())


def load(path: str | Path) -> DemoFile:
    """Read a schema-1 file and check all of it (shapes, dtypes, NaN or inf in any array); raise
    ValueError naming the file and the problem for a bad one."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no demonstration file at {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(
            f"{path} is not an .npz archive; for D4RL, Minari or imitation files use "
            "ilfo.demos.load_any (or `ilfo demos convert` to make an ilfo file)"
        )
    check_npz(path)  # encrypted, foreign compression, a header declaring terabytes
    try:
        with np.load(path, allow_pickle=False) as archive:
            data = {k: archive[k] for k in archive.files}
    except ValueError as err:
        if "allow_pickle" in str(err):
            raise ValueError(
                f"{path} holds pickled Python objects, which ilfo never loads"
            ) from None
        raise ValueError(f"{path} is not a readable .npz archive ({err})") from None
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, KeyError, TypeError) as err:
        raise ValueError(f"{path} is not a readable .npz archive ({err})") from None
    for key in ("schema_version", "episode_lengths", "observations"):
        if key not in data:
            raise ValueError(f"{path} lacks the key {key!r}: not an ilfo demonstration file")
    try:
        schema = int(data["schema_version"])
    except (TypeError, ValueError):
        raise ValueError(f"{path}: schema_version is not a number") from None
    if schema != SCHEMA_VERSION:
        raise ValueError(f"{path} has schema {schema}, expected 1")
    lengths = numeric_array(data["episode_lengths"], "episode_lengths", path)
    obs = numeric_array(data["observations"], "observations", path)
    if lengths.dtype.kind not in "iu" or lengths.ndim != 1 or len(lengths) == 0:
        raise ValueError(f"{path}: episode_lengths must be a non-empty 1-D array of integers")
    lengths = lengths.astype(np.int64)
    if obs.ndim != 2 or (lengths < 2).any() or lengths.sum() != len(obs):
        raise ValueError(
            f"{path}: observations {obs.shape} do not match episode_lengths (each episode needs "
            "T + 1 >= 2 observations, all episodes end to end)"
        )
    bounds = np.concatenate([[0], np.cumsum(lengths)])
    step_bounds = np.concatenate([[0], np.cumsum(lengths - 1)])
    extras = {}
    for name in ("actions", "rewards", "terminated"):
        if name in data:
            if data[name].ndim == 0 or len(data[name]) != step_bounds[-1]:
                raise ValueError(
                    f"{path}: {name} has shape {data[name].shape}, not {step_bounds[-1]} rows"
                )
            extras[name] = data[name]
    episodes = [
        Episode(
            observations=obs[bounds[i] : bounds[i + 1]],
            **{k: v[step_bounds[i] : step_bounds[i + 1]] for k, v in extras.items()},
        )
        for i in range(len(lengths))
    ]
    try:
        provenance = json.loads(str(data["provenance"])) if "provenance" in data else {}
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: provenance is not valid JSON ({err})") from None
    if not isinstance(provenance, dict):
        raise ValueError(f"{path}: provenance must be a JSON object")
    env_id = str(data["env_id"]) if "env_id" in data else ""
    return DemoFile(episodes=checked_episodes(episodes, path), env_id=env_id, provenance=provenance)


def numeric_array(arr: np.ndarray, name: str, path: str | Path) -> np.ndarray:
    arr = np.asarray(arr)
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"{path}: {name!r} holds {arr.dtype} data, not numbers")
    return arr


def checked_episodes(episodes: list[Episode], path: str | Path) -> list[Episode]:
    """Episodes with observations (T + 1, d) as floats, actions (T, a), rewards (T,), all finite
    and with the same d and a throughout, terminated (T,) boolean; raise ValueError naming the
    first problem."""
    if not episodes:
        raise ValueError(f"{path} holds no episodes")
    out = []
    obs_dim = act_dim = None
    for i, ep in enumerate(episodes):
        where = f"{path}: episode {i}"
        obs = numeric_array(ep.observations, "observations", path)
        if obs.ndim != 2 or len(obs) < 2:
            raise ValueError(
                f"{where}: observations have shape {obs.shape}, not (T + 1, d), T >= 1"
            )
        if obs.dtype.kind != "f":
            obs = obs.astype(np.float64)
        if not np.isfinite(obs).all():
            raise ValueError(f"{where}: observations contain NaN or inf")
        if obs_dim is None:
            obs_dim = obs.shape[1]
        if obs.shape[1] != obs_dim or obs_dim == 0:
            raise ValueError(
                f"{where}: observations have dim {obs.shape[1]}, episode 0 has {obs_dim}"
            )
        steps = len(obs) - 1
        actions = ep.actions
        if actions is not None:
            actions = numeric_array(actions, "actions", path)
            if actions.ndim == 1:
                actions = actions[:, None]
            if actions.ndim != 2 or len(actions) != steps:
                raise ValueError(f"{where}: actions have shape {actions.shape}, not ({steps}, a)")
            if act_dim is None:
                act_dim = actions.shape[1]
            if actions.shape[1] != act_dim:
                raise ValueError(
                    f"{where}: actions have dim {actions.shape[1]}, an earlier episode {act_dim}"
                )
            if not np.isfinite(actions).all():
                raise ValueError(f"{where}: actions contain NaN or inf")
        rewards = ep.rewards
        if rewards is not None:
            rewards = numeric_array(rewards, "rewards", path)
            if rewards.ndim == 2 and rewards.shape[1:] == (1,):
                rewards = rewards[:, 0]
            if rewards.shape != (steps,):
                raise ValueError(f"{where}: rewards have shape {rewards.shape}, not ({steps},)")
            rewards = rewards.astype(np.float64)
            if not np.isfinite(rewards).all():
                raise ValueError(f"{where}: rewards contain NaN or inf")
        terminated = None if ep.terminated is None else np.asarray(ep.terminated)
        if terminated is not None and (
            terminated.dtype != np.bool_ or terminated.shape != (steps,)
        ):
            raise ValueError(
                f"{where}: terminated must be boolean of shape ({steps},), got "
                f"{terminated.dtype} {terminated.shape}"
            )
        out.append(Episode(obs, actions, rewards, terminated))
    return out
