"""Run directories: created once and owned by one process; checkpoints found by what is on disk.

What a run directory holds is described in ``ilfo.training``. The rules here keep many runs
started together (a sweep) from mixing, and keep a run resumable whatever moment it was killed:

- ``create_run_dir`` makes a new directory with an exclusive ``mkdir``: two runs started in the
  same second with the same name get ``NAME`` and ``NAME-2``, never one directory.
- ``RunLock`` is an advisory lock (``flock``) on ``RUN/.lock`` held while a process writes the
  run; a second process that would write there (a duplicate start, two resumes) is refused. The
  kernel drops the lock when its process dies, so a killed run can be resumed at once.
- A checkpoint is written in ``checkpoints/.tmp_step_N`` and renamed to ``checkpoints/step_N``
  when complete, so every ``step_N`` directory is a whole checkpoint; ``latest_checkpoint`` picks
  the newest by scanning them (no pointer file that a kill could leave missing or stale).
- A run with no complete checkpoint starts again from step 0 only where it holds nothing a run
  writes after its first checkpoint (``results_past_first_checkpoint``): a finished run whose
  checkpoints were removed keeps its results, and is not resumed.
- Its records are read as today's format through ``migrations`` (``read_run_config``), which
  upgrades an older run's; what a run writes says its format.
"""

from __future__ import annotations

import csv
import errno
import fcntl
import json
import math
import os
import re
import shutil
import signal
from pathlib import Path
from typing import Any

from ilfo.files import read_json
from ilfo.training.config import TrainConfig

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.csv"
DEMOS_RECORD_FILE = "demos.json"  # which demo file an imitation run imitates (its sha256)
CHECKPOINTS_DIR = "checkpoints"
LOCK_FILE = ".lock"
STATE_FILE = "state.json"
CHECKPOINT_FILES = (STATE_FILE, "agent.msgpack")
"""Files every checkpoint has (``state.json`` is written last), beside its replay buffer
(``REPLAY_FILE``, or ``REPLAY_OMITTED`` in a snapshot's checkpoint)."""
REPLAY_FILE = "replay.npz"
REPLAY_OMITTED = "replay.omitted"
"""Written in place of the replay buffer by ``snapshot_run`` (JSON: what was left out)."""
FAULT_ENV = "ILFO_FAULT_KILL_AT"
"""Test hook: ``NAME[:K]`` kills the process with SIGKILL at the K-th (default first) time it
reaches the fault point NAME (see ``fault_point``)."""

_STEP_DIR = re.compile(r"step_(\d+)")
_fault_hits: dict[str, int] = {}


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
        has_replay = (path / REPLAY_FILE).is_file() or (path / REPLAY_OMITTED).is_file()
        if match and has_replay and all((path / name).is_file() for name in CHECKPOINT_FILES):
            found.append((int(match.group(1)), path))
    return sorted(found)


def damaged_checkpoints(run_dir: str | Path) -> list[Path]:
    """The run's ``step_*`` checkpoint directories that lack a file, oldest first. Checkpoints
    are renamed into place only once written, so these are checkpoints someone removed files
    from (typically ``replay.npz``, to free disk), not half-written ones."""
    root = Path(run_dir) / CHECKPOINTS_DIR
    if not root.is_dir():
        return []
    complete = {path for _, path in checkpoint_steps(run_dir)}
    damaged = [
        path
        for path in root.iterdir()
        if _STEP_DIR.fullmatch(path.name) and path.is_dir() and path not in complete
    ]
    return sorted(damaged, key=_step)


def _step(checkpoint: Path) -> int:
    """The step of a ``step_N`` checkpoint directory."""
    return int(checkpoint.name.removeprefix("step_"))


def newest_checkpoint_is_damaged(run_dir: str | Path) -> Path | None:
    """The newest ``step_*`` directory where it is a damaged checkpoint (``damaged_checkpoints``)
    newer than every complete one, else None: resuming from an older checkpoint would drop the
    steps and metrics logged after it."""
    damaged, latest = damaged_checkpoints(run_dir), latest_checkpoint(run_dir)
    if damaged and (latest is None or _step(damaged[-1]) > _step(latest)):
        return damaged[-1]
    return None


def damaged_checkpoint_message(path: Path) -> str:
    """What is wrong with damaged checkpoint ``path`` and how to continue from it."""
    missing = [name for name in CHECKPOINT_FILES if not (path / name).is_file()]
    if not missing:  # only the replay buffer is gone
        return (
            f"checkpoint {path} has no {REPLAY_FILE} (removed?): put it back, or (off-policy "
            f"runs; an on-policy run needs its pending batch) continue without it as from a "
            f"snapshot (the buffer refilled by the policy) after `touch {path / REPLAY_OMITTED}`"
        )
    return (
        f"checkpoint {path} lacks {', '.join(missing)}: put the files back, or delete the "
        "directory to continue from an older checkpoint"
    )


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The newest complete checkpoint directory of a run, or None."""
    steps = checkpoint_steps(run_dir)
    return steps[-1][1] if steps else None


def remove_incomplete_checkpoints(run_dir: str | Path) -> None:
    """Delete what a killed checkpoint write left: ``.tmp_step_*`` directories, and checkpoints
    older than the newest complete one whose removal was cut short."""
    root = Path(run_dir) / CHECKPOINTS_DIR
    if not root.is_dir():
        return
    for path in root.glob(".tmp_step_*"):
        shutil.rmtree(path, ignore_errors=True)
    latest = latest_checkpoint(run_dir)
    for path in damaged_checkpoints(run_dir):
        if latest is not None and _step(path) < _step(latest):
            shutil.rmtree(path, ignore_errors=True)


CHECKPOINT_CLOCK_SLACK_S = 1.0
"""How far a row's ``wall_time`` must pass ``checkpoint_minutes`` for a checkpoint to have been
due after it for certain: the loop times the clock's interval from a moment just after the one
``wall_time`` counts from."""


def results_past_first_checkpoint(run_dir: str | Path, config: TrainConfig) -> str | None:
    """What run ``run_dir`` holds that only a run past its first checkpoint writes, in words
    (``"6 metrics rows to step 600, policy.msgpack, best_policy.msgpack"``), else None.

    A run writes its metrics row of an episode, then the checkpoint that falls due at it
    (``config.checkpoint_every`` steps, ``config.checkpoint_minutes`` of training, the end of
    its steps), so one killed before (or while writing) its first checkpoint holds its config,
    the rows up to the one that checkpoint fell due at, and the best policy of their
    evaluations: what a start from step 0 writes again. A row after that one, a final policy
    (written after the last checkpoint) or a best policy of a later step show that a
    checkpoint was written: with none left (``checkpoints/`` removed), a start from step 0
    would delete them. ``config`` is the run's (its checkpoint settings)."""
    run_dir = Path(run_dir)
    rows = _logged_rows(run_dir / METRICS_FILE)
    first_due_step = min(config.checkpoint_every, config.steps)
    clock_s = 60.0 * config.checkpoint_minutes or math.inf
    due = next(
        (
            k
            for k, (step, wall_time) in enumerate(rows)
            if step >= first_due_step or wall_time >= clock_s + CHECKPOINT_CLOCK_SLACK_S
        ),
        None,
    )
    past = (run_dir / FINAL_POLICY_FILE).is_file() or (due is not None and due < len(rows) - 1)
    best_step = _best_policy_step(run_dir)
    if best_step is not None and best_step > (rows[due][0] if due is not None else first_due_step):
        past = True
    if not past:
        return None
    held = [f"{len(rows):,} metrics rows to step {rows[-1][0]:,}"] if rows else []
    held += [
        name
        for name in (FINAL_POLICY_FILE, BEST_POLICY_FILE, BEST_POLICY_INFO)
        if (run_dir / name).is_file()
    ]
    return ", ".join(held)


def _logged_rows(path: Path) -> list[tuple[int, float]]:
    """(step, wall_time) of each whole row of a metrics.csv (none where it is missing); a row
    a kill cut short, or one without a step, is skipped, as ``metrics.truncate_metrics`` drops
    it. A row without a wall time has ``-inf``."""
    if not path.is_file():
        return []
    rows = []
    with path.open(newline="", encoding="utf-8", errors="replace") as f:
        for row in csv.DictReader(f):
            step = row.get("step")
            if None in row.values() or step is None or not step.isdigit():
                continue
            try:
                wall_time = float(row.get("wall_time") or "-inf")
            except ValueError:
                wall_time = -math.inf
            rows.append((int(step), wall_time))
    return rows


def _best_policy_step(run_dir: Path) -> int | None:
    """The step of the run's best policy (``BEST_POLICY_INFO``), None without a readable one."""
    path = run_dir / BEST_POLICY_INFO
    if not path.is_file():
        return None
    try:
        return int(json.loads(path.read_text(encoding="utf-8"))["step"])
    except (ValueError, KeyError, TypeError, RecursionError):
        return None


def read_demos_record(run_dir: str | Path) -> dict[str, Any] | None:
    """A run's ``demos.json`` (``build.DemoSource.as_record``: the demo file it imitates, its
    sha256, the demos' mean return); None for a run without demos or one older than the
    record. A ValueError names a damaged file."""
    path = Path(run_dir) / DEMOS_RECORD_FILE
    return read_json_object(path) if path.is_file() else None


def read_json_object(path: Path) -> dict[str, Any]:
    """The JSON object in file ``path``; a ValueError names a file that holds none."""
    raw = read_json(path)  # a ValueError naming a file not UTF-8, not JSON or nested too deeply
    if not isinstance(raw, dict):
        raise ValueError(f"{path} must hold a JSON object, not {type(raw).__name__}")
    return raw


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


BEST_POLICY_FILE = "best_policy.msgpack"
BEST_POLICY_INFO = "best_policy.json"  # the step and evaluation of best_policy.msgpack
FINAL_POLICY_FILE = "policy.msgpack"


DISTANCES_FILE, SOLVERS_FILE = "distances.json", "solvers.json"
MEASURE_FILES = (DISTANCES_FILE, SOLVERS_FILE)
"""Measures of a run's final rollouts that ``ilfo reproduce`` keeps in the run (table3's
distances, the solver figure's costs: minutes to hours of compute each)."""


def partial_measure_file(name: str) -> str:
    """Where a measure kept as ``name`` keeps its pairs while it is measured."""
    return f".{Path(name).stem}.partial.json"


SNAPSHOT_FILES = (
    CONFIG_FILE,
    DEMOS_RECORD_FILE,
    METRICS_FILE,
    FINAL_POLICY_FILE,
    BEST_POLICY_FILE,
    BEST_POLICY_INFO,
    "learning_curve.png",
    *MEASURE_FILES,
    *(partial_measure_file(name) for name in MEASURE_FILES),
)
"""What ``snapshot_run`` copies besides the newest checkpoint (each where it exists)."""


def copy_results(run_dir: Path, out: Path) -> None:
    """Copy the ``SNAPSHOT_FILES`` run ``run_dir`` holds (its config, demos record, metrics,
    policies) into directory ``out``, which must exist."""
    for name in SNAPSHOT_FILES:
        if (run_dir / name).is_file():
            shutil.copy2(run_dir / name, out / name)
