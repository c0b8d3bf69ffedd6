"""Run directories: created once and owned by one process; checkpoints found by what is on disk.

What a run directory holds is described in :mod:`ilfo.train`. The rules here keep many runs
started together (a sweep) from mixing, and keep a run resumable whatever moment it was killed:

- ``create_run_dir`` makes a new directory with an exclusive ``mkdir``: two runs started in the
  same second with the same name get ``NAME`` and ``NAME-2``, never one directory.
- ``RunLock`` is an advisory lock (``flock``) on ``RUN/.lock`` held while a process writes the
  run; a second process that would write there (a duplicate start, two resumes) is refused. The
  kernel drops the lock when its process dies, so a killed run can be resumed at once.
- A checkpoint is written in ``checkpoints/.tmp_step_N`` and renamed to ``checkpoints/step_N``
  when complete, so every ``step_N`` directory is a whole checkpoint; ``latest_checkpoint`` picks
  the newest by scanning them (no pointer file that a kill could leave missing or stale).
- ``read_run_config``, ``load_msgpack`` and ``load_npz`` turn a damaged file into a
  ``ValueError`` that names the file and what is wrong.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import shutil
import signal
import zipfile
from pathlib import Path
from typing import Any, TypeVar

import flax.serialization
import jax
import numpy as np

CONFIG_FILE = "config.json"
CHECKPOINTS_DIR = "checkpoints"
LOCK_FILE = ".lock"
CHECKPOINT_FILES = ("state.json", "agent.msgpack", "replay.npz")
"""Files every checkpoint has (``state.json`` is written last)."""
FAULT_ENV = "ILFO_FAULT_KILL_AT"
"""Test hook: ``NAME[:K]`` kills the process with SIGKILL at the K-th (default first) time it
reaches the fault point NAME (see ``fault_point``)."""

_STEP_DIR = re.compile(r"step_(\d+)")
_fault_hits: dict[str, int] = {}
T = TypeVar("T")


class RunDirInUse(ValueError):
    """Another process holds the run directory's lock."""


def create_run_dir(parent: str | Path, name: str) -> Path:
    """A new, empty directory ``parent/name`` (``name-2``, ``name-3``, ... where taken), made
    with an exclusive mkdir so that runs started at the same moment never share one."""
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    for k in range(1, 10_000):
        path = parent / (name if k == 1 else f"{name}-{k}")
        try:
            path.mkdir()
        except FileExistsError:
            continue
        return path
    raise FileExistsError(errno.EEXIST, "no free run directory name", str(parent / name))


class RunLock:
    """Exclusive ownership of a run directory for as long as the lock is held (see module)."""

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)
        self._file: Any = None

    @property
    def held(self) -> bool:
        """Whether this object holds the lock now."""
        return self._file is not None

    def acquire(self) -> RunLock:
        """Take the lock, or raise ``RunDirInUse`` naming the process that holds it."""
        if self._file is not None:
            return self
        path = self.run_dir / LOCK_FILE
        f = path.open("a+")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            owner = f.read().strip() or "?"
            f.close()
            raise RunDirInUse(
                f"{self.run_dir} is in use by another run (process {owner}); wait for it to "
                "end, or choose another directory"
            ) from None
        f.seek(0)
        f.truncate()
        f.write(f"{os.getpid()}\n")
        f.flush()
        self._file = f
        return self

    def release(self) -> None:
        """Give the lock up (closing the file releases it)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def checkpoint_steps(run_dir: str | Path) -> list[tuple[int, Path]]:
    """The run's complete checkpoints as (step, directory), oldest first."""
    root = Path(run_dir) / CHECKPOINTS_DIR
    if not root.is_dir():
        return []
    found = []
    for path in root.iterdir():
        match = _STEP_DIR.fullmatch(path.name)
        if match and all((path / name).is_file() for name in CHECKPOINT_FILES):
            found.append((int(match.group(1)), path))
    return sorted(found)


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The newest complete checkpoint directory of a run, or None."""
    steps = checkpoint_steps(run_dir)
    return steps[-1][1] if steps else None


def remove_incomplete_checkpoints(run_dir: str | Path) -> None:
    """Delete what a killed checkpoint write left: ``.tmp_step_*`` directories, and the stale
    ``latest`` pointer of runs written before checkpoints were found by scanning."""
    root = Path(run_dir) / CHECKPOINTS_DIR
    if not root.is_dir():
        return
    for path in root.glob(".tmp_step_*"):
        shutil.rmtree(path, ignore_errors=True)
    for name in ("latest", ".latest.tmp"):
        (root / name).unlink(missing_ok=True)


def read_run_config(run_dir: str | Path) -> dict[str, Any]:
    """A run directory's config.json as a dict, with a clear error for a missing or damaged one
    (field names and values are checked by ``TrainConfig``: see ``train.config_from_dict``)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} is not a run directory (no {CONFIG_FILE})")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as err:
        raise ValueError(f"{path} is not UTF-8 text ({err.reason} at byte {err.start})") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"{path} is not valid JSON ({err}); it may be truncated") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{path} must hold a JSON object of settings, not {type(raw).__name__}")
    return raw


def write_json_atomic(path: str | Path, value: Any) -> None:
    """Write ``value`` as JSON to ``path`` through a temporary file and a rename: a reader (or a
    kill) never sees a half-written file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(value, indent=2) + "\n")
    os.replace(tmp, path)


def load_msgpack(template: T, path: str | Path, what: str) -> T:
    """``path``'s flax msgpack restored onto ``template``, checked to have its structure and
    every array's shape; a ValueError names the file otherwise.

    ``what`` says what the file holds ("policy", "agent checkpoint"), for the messages."""
    path = Path(path)
    try:
        data = path.read_bytes()
        restored = flax.serialization.from_bytes(template, data)
    except (ValueError, KeyError, TypeError, IndexError, AttributeError) as err:
        # msgpack's errors (truncated, garbage) are ValueErrors; a foreign tree, Key/TypeError.
        raise ValueError(f"{path} is not a readable {what} file ({err})") from None
    expected = jax.tree_util.tree_leaves_with_path(template)
    got = jax.tree_util.tree_leaves(restored)
    if len(expected) != len(got):
        raise ValueError(f"{path}: the {what} does not have this run's structure")
    for (key, want), have in zip(expected, got, strict=True):
        want_shape, have_shape = np.shape(want), np.shape(have)
        if want_shape != have_shape:
            raise ValueError(
                f"{path}: {what} entry {jax.tree_util.keystr(key)} has shape {have_shape}, this "
                f"run's config makes {want_shape} (were the env or the network sizes changed?)"
            )
    return restored


def load_npz(path: str | Path, what: str) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` written by ilfo (never unpickled), or a ValueError naming the
    file: not a zip archive, truncated, or holding objects."""
    path = Path(path)
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a {what} file (not an .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {k: archive[k] for k in archive.files}
    except ValueError as err:
        if "allow_pickle" in str(err):
            raise ValueError(f"{path}: {what} file holds Python objects, not arrays") from None
        raise ValueError(f"{path} is not a readable {what} file ({err})") from None
    except (zipfile.BadZipFile, OSError, EOFError, KeyError) as err:
        raise ValueError(f"{path} is not a readable {what} file ({err}); truncated?") from None


def fault_point(name: str) -> None:
    """Kill this process (SIGKILL, as a crash or an OOM kill would) when ``FAULT_ENV`` names
    this point; for the tests that check a run survives a kill anywhere."""
    spec = os.environ.get(FAULT_ENV)
    if not spec:
        return
    target, _, count = spec.partition(":")
    if target != name:
        return
    _fault_hits[name] = _fault_hits.get(name, 0) + 1
    if _fault_hits[name] >= int(count or 1):
        os.kill(os.getpid(), signal.SIGKILL)
