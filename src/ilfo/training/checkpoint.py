"""Checkpoints: the whole state of a run at an episode boundary, written atomically.

A checkpoint is the directory ``checkpoints/step_N`` (N the environment steps done): the agent
state (``agent.msgpack``), the replay buffer (``replay.npz``), the random-phase states kept
for the normaliser (``random_states.npz``), the episode reward's state (``state.json``'s
``reward_state`` and ``reward_arrays.npz``), the best policy so far (``best_policy.msgpack`` and
``best_policy.json``, where there is one) and the counters (``state.json``, written last).
Every other source of randomness is derived from (seed, episode index), so a run resumed from
a checkpoint reproduces the uninterrupted one exactly. It is written in ``.tmp_step_N`` and
flushed to the disk and renamed once complete; older checkpoints are removed after, so a kill
(or a power loss) at any moment leaves at least one complete checkpoint
(``run_dir.latest_checkpoint`` finds the newest).
"""

from __future__ import annotations

import json
import os
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import flax.serialization
import numpy as np

from ilfo.files import load_msgpack, load_npz, naming, sync_dir, sync_tree
from ilfo.replay import ReplayBuffer
from ilfo.rewards import RewardState
from ilfo.training.run_dir import (
    BEST_POLICY_FILE,
    BEST_POLICY_INFO,
    CHECKPOINTS_DIR,
    REPLAY_FILE,
    REPLAY_OMITTED,
    checkpoint_steps,
    fault_point,
    latest_checkpoint,
)

CHECKPOINT_SCHEMA = 1
REWARD_ARRAYS_FILE = "reward_arrays.npz"
# Written by ilfo before 2026-12-01 (OOPS's generator and warm starts); still read.
_OLD_RNG_KEY, _OLD_POTENTIALS_FILE = "rewarder_rng", "rewarder_potentials.npz"


@dataclass
class Checkpoint:
    """What a run needs to continue exactly."""

    step: int
    episode: int
    elapsed: float
    """Wall-clock seconds of training so far."""
    last_eval: dict[str, float]
    best_eval: dict[str, float]
    agent_state: Any
    buffer: ReplayBuffer | None
    """None when loaded without the replay buffer (to read the policy only)."""
    random_states: list[np.ndarray] = field(default_factory=list)
    """States of the random phase, until the normaliser is fitted from them."""
    reward_state: RewardState | None = None
    """The episode reward's ``state()``; None for the task reward."""
    refill_until: int = 0
    """Updates wait until this step: a run continued from a snapshot (no replay buffer) first
    refills its buffer with the policy's own steps."""
    buffer_omitted: bool = False
    """The checkpoint is a snapshot's: its replay buffer was left out (``run_dir.snapshot_run``)."""


def save_checkpoint(run_dir: Path, ckpt: Checkpoint) -> Path:
    """Write ``ckpt`` as ``run_dir/checkpoints/step_N`` (see the module) and return it."""
    root = Path(run_dir) / CHECKPOINTS_DIR
    final = root / f"step_{ckpt.step:09d}"
    if latest_checkpoint(run_dir) == final:
        return final  # this step is checkpointed already: the state has not changed since
    tmp = root / f".tmp_step_{ckpt.step:09d}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        _write_files(run_dir, tmp, ckpt)
    except OSError:  # a full disk: the error names the file; the partial copy frees its space
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    # Its files on the disk (``_write_files`` flushes them) before the rename, and the rename
    # before the older checkpoints go: else a power loss could leave the new name with empty
    # files and no older checkpoint.
    fault_point("checkpoint_before_rename")
    os.replace(tmp, final)
    sync_dir(root)
    fault_point("checkpoint_before_cleanup")
    for _, old in checkpoint_steps(run_dir)[:-1]:
        shutil.rmtree(old, ignore_errors=True)
    return final


def _write_files(run_dir: Path, tmp: Path, ckpt: Checkpoint) -> None:
    """The checkpoint's files in ``tmp``, flushed to the disk; an OSError names the file."""
    with naming(tmp / "agent.msgpack"):
        (tmp / "agent.msgpack").write_bytes(flax.serialization.to_bytes(ckpt.agent_state))
    assert ckpt.buffer is not None, "a checkpoint needs the replay buffer"
    with naming(tmp / REPLAY_FILE):
        ckpt.buffer.save(tmp / REPLAY_FILE)
    if ckpt.random_states:
        with naming(tmp / "random_states.npz"):
            np.savez(tmp / "random_states.npz", *ckpt.random_states)
    reward = ckpt.reward_state
    if reward is not None and reward.arrays:
        with naming(tmp / REWARD_ARRAYS_FILE):
            np.savez(tmp / REWARD_ARRAYS_FILE, **reward.arrays)
    for name in BEST_FILES:  # see restore_best_policy
        if (Path(run_dir) / name).is_file():
            with naming(tmp / name):
                _link_or_copy(Path(run_dir) / name, tmp / name)
    meta = {
        "schema": CHECKPOINT_SCHEMA,
        "step": ckpt.step,
        "episode": ckpt.episode,
        "elapsed": ckpt.elapsed,
        "last_eval": ckpt.last_eval,
        "best_eval": ckpt.best_eval,
        "reward_state": None if reward is None else reward.values,
        "refill_until": ckpt.refill_until,
    }
    with naming(tmp / "state.json"):
        (tmp / "state.json").write_text(json.dumps(meta))  # last: see run_dir.CHECKPOINT_FILES
    with naming(tmp):
        sync_tree(tmp)


BEST_FILES = (BEST_POLICY_FILE, BEST_POLICY_INFO)


def restore_best_policy(run_dir: Path, ckpt_dir: Path | None, best_eval: dict[str, float]) -> None:
    """Put back the best policy that checkpoint ``ckpt_dir`` knows (``best_eval``, its record);
    with no checkpoint (a run starting again from step 0), remove it.

    An evaluation after the checkpoint may have written a better one. An exact continuation
    writes it again; one that is not exact (from a snapshot, or on other hardware) would keep
    a best policy from a future it discarded, at a step whose metrics row it rewrites.
    Checkpoints written before ilfo kept the best policy in them have no copy: a best policy
    newer than such a checkpoint is then left with a warning.
    """
    run_dir = Path(run_dir)
    if ckpt_dir is not None and all((ckpt_dir / name).is_file() for name in BEST_FILES):
        for name in BEST_FILES:
            tmp = run_dir / f".{name}.tmp"
            shutil.copyfile(ckpt_dir / name, tmp)
            os.replace(tmp, run_dir / name)
        return
    info_path = run_dir / BEST_POLICY_INFO
    if not info_path.is_file():
        return
    try:
        best_step = int(json.loads(info_path.read_text(encoding="utf-8"))["step"])
    except (ValueError, KeyError, TypeError, RecursionError) as err:
        raise ValueError(f"{info_path} is not a readable best-policy record ({err})") from None
    if not best_eval:  # no best policy yet at the checkpoint: the files came after it
        for name in BEST_FILES:
            (run_dir / name).unlink(missing_ok=True)
    elif best_step != best_eval.get("step"):
        warnings.warn(
            f"{run_dir / BEST_POLICY_FILE} is from step {best_step}, after checkpoint "
            f"{ckpt_dir}, which holds no copy of its own best (step "
            f"{int(best_eval['step'])}; written by an earlier ilfo): it stays, though a "
            "continuation that is not exact may not reach it again",
            stacklevel=3,
        )


def _link_or_copy(src: Path, dst: Path) -> None:
    """A hard link where the file system allows (the run replaces, never rewrites, its best
    policy files, so the link keeps the checkpoint's version), else a copy."""
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def load_checkpoint(
    ckpt: Path, agent_template: Any, buffer_dims: tuple[int, int] | None
) -> Checkpoint:
    """Read checkpoint directory ``ckpt``; the agent state is restored onto ``agent_template``
    (its structure and shapes checked), the replay buffer only where ``buffer_dims`` (obs,
    action) is given, and checked against it. A damaged or mismatched file is a ValueError
    naming it."""
    state_path = ckpt / "state.json"
    try:
        meta = json.loads(state_path.read_text(encoding="utf-8"))
        if meta.get("schema") != CHECKPOINT_SCHEMA:
            raise ValueError(f"checkpoint schema {meta.get('schema')}, expected 1")
        counters = int(meta["step"]), int(meta["episode"]), float(meta["elapsed"])
        refill_until = int(meta.get("refill_until", 0))
        evals = dict(meta["last_eval"]), dict(meta.get("best_eval", {}))
        if "reward_state" in meta:
            values = meta["reward_state"]
        else:
            values = None if meta[_OLD_RNG_KEY] is None else {"rng": meta[_OLD_RNG_KEY]}
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as err:
        raise ValueError(f"{state_path} is not a readable checkpoint state ({err})") from None
    agent_state = load_msgpack(agent_template, ckpt / "agent.msgpack", "agent checkpoint")
    buffer = None
    omitted = not (ckpt / REPLAY_FILE).is_file() and (ckpt / REPLAY_OMITTED).is_file()
    if buffer_dims is not None and not omitted:
        buffer = ReplayBuffer.load(ckpt / REPLAY_FILE)
        if (buffer.obs_dim, buffer.action_dim) != buffer_dims:
            raise ValueError(
                f"{ckpt / REPLAY_FILE}: transitions of (obs, action) dims "
                f"{(buffer.obs_dim, buffer.action_dim)}, this run's config makes {buffer_dims}"
            )
    arrays_path = next(
        (p for p in (ckpt / REWARD_ARRAYS_FILE, ckpt / _OLD_POTENTIALS_FILE) if p.is_file()), None
    )
    arrays = {} if arrays_path is None else load_npz(arrays_path, "reward state")
    reward_state = None if values is None and not arrays else RewardState(values or {}, arrays)
    random_states = []
    if (ckpt / "random_states.npz").is_file():
        saved = load_npz(ckpt / "random_states.npz", "random-phase states")
        random_states = [saved[k] for k in sorted(saved, key=lambda n: int(n.split("_")[-1]))]
    return Checkpoint(
        *counters,
        *evals,
        agent_state,
        buffer,
        random_states,
        reward_state,  # type: ignore[arg-type]
        refill_until,
        omitted,
    )
