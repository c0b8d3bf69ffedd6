"""Checkpoints: the whole state of a run at an episode boundary, written atomically.

A checkpoint is the directory ``checkpoints/step_N`` (N the environment steps done): the agent
state (``agent.msgpack``), the replay buffer (``replay.npz``), the loop's state (``LoopState``:
``state.json``'s ``loop``, with its random-phase states kept for the normaliser in
``random_states.npz``; TD7's policy checkpoint, its policy in ``checkpoint_policy.msgpack``),
the episode reward's state (``state.json``'s ``reward_state``, with its arrays in
``reward_arrays.npz``) and the best policy so far (``best_policy.msgpack`` and
``best_policy.json``, where there is one); ``state.json``, written last, says its format
(``migrations.CHECKPOINT_FORMAT``: an older checkpoint is read through ``migrations``).
Every other source of randomness is derived from (seed, episode index), so a run resumed from
a checkpoint reproduces the uninterrupted one exactly. It is written in ``.tmp_step_N`` and
flushed to the disk and renamed once complete; older checkpoints are removed after, so a kill
(or a power loss) at any moment leaves at least one complete checkpoint
(``run_dir.latest_checkpoint`` finds the newest).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import flax.serialization
import numpy as np

from ilfo.agents import policy_of
from ilfo.agents.policy_checkpoints import PolicyCheckpoint, canonical
from ilfo.algos import AGENT_PARTS, ALGOS
from ilfo.files import check_new_copy_dir, load_msgpack, load_npz, naming, sync_dir, sync_tree
from ilfo.replay import ReplayBuffer
from ilfo.rewards import RewardState
from ilfo.training.migrations import (
    CHECKPOINT_FORMAT,
    CHECKPOINT_KEY,
    keep_best_policy_of_older_checkpoint,
    read_run_config,
    upgrade_checkpoint_state,
)
from ilfo.training.run_dir import (
    BEST_POLICY_FILE,
    BEST_POLICY_INFO,
    CHECKPOINTS_DIR,
    REPLAY_FILE,
    REPLAY_OMITTED,
    STATE_FILE,
    RunLock,
    checkpoint_steps,
    copy_results,
    damaged_checkpoint_message,
    fault_point,
    latest_checkpoint,
    newest_checkpoint_is_damaged,
)

RANDOM_STATES_FILE = "random_states.npz"
REWARD_ARRAYS_FILE = "reward_arrays.npz"
CHECKPOINT_POLICY_FILE = "checkpoint_policy.msgpack"
"""TD7's checkpoint policy (``LoopState.policy_checkpoint``), where there is one."""


@dataclass(frozen=True)
class LoopState:
    """The training loop's own state between episodes, which a checkpoint keeps and a resume
    puts back whole (``Trainer.loop_state``); every other source of its randomness is derived
    from (seed, episode index). Replaced, never changed in place."""

    step: int = 0
    """Environment steps done."""
    episode: int = 0
    """Episodes done."""
    elapsed: float = 0.0
    """Wall-clock seconds of training so far."""
    last_eval: dict[str, float] = field(default_factory=dict)
    """The last evaluation's metrics; empty before the first."""
    best_eval: dict[str, float] = field(default_factory=dict)
    """The best evaluation so far by ``config.best_by``, with its step; empty before the
    first."""
    random_states: tuple[np.ndarray, ...] = ()
    """The random phase's states, one array an episode, until the normaliser is fitted from
    them."""
    refill_until: int = 0
    """Updates wait until this step: a run continued from a snapshot (no replay buffer) first
    refills its buffer with the policy's own steps."""
    policy_checkpoint: PolicyCheckpoint | None = None
    """TD7's checkpoint policy and its assessment under way (``agents.policy_checkpoints``),
    where the agent is evaluated with one; None otherwise, and before its first episode."""


@dataclass(frozen=True)
class Checkpoint:
    """What a run needs to continue exactly."""

    loop: LoopState
    agent_state: Any
    buffer: ReplayBuffer | None
    """None when loaded without the replay buffer (to read the policy only)."""
    reward_state: RewardState | None = None
    """The episode reward's ``state()``; None for the task reward."""
    buffer_omitted: bool = False
    """The checkpoint is a snapshot's: its replay buffer was left out (``snapshot_run``)."""


def save_checkpoint(run_dir: Path, ckpt: Checkpoint) -> Path:
    """Write ``ckpt`` as ``run_dir/checkpoints/step_N`` (see the module) and return it."""
    root = Path(run_dir) / CHECKPOINTS_DIR
    final = root / f"step_{ckpt.loop.step:09d}"
    if latest_checkpoint(run_dir) == final:
        return final  # this step is checkpointed already: the state has not changed since
    tmp = root / f".tmp_step_{ckpt.loop.step:09d}"
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
    loop = ckpt.loop
    if loop.random_states:
        with naming(tmp / RANDOM_STATES_FILE):
            np.savez(tmp / RANDOM_STATES_FILE, *loop.random_states)
    reward = ckpt.reward_state
    if reward is not None and reward.arrays:
        with naming(tmp / REWARD_ARRAYS_FILE):
            # numpy's stubs let **arrays fill allow_pickle (a bool); these keys are array names.
            np.savez(tmp / REWARD_ARRAYS_FILE, **reward.arrays)  # type: ignore[arg-type]
    checkpoint = loop.policy_checkpoint
    if checkpoint is not None and checkpoint.policy is not None:
        with naming(tmp / CHECKPOINT_POLICY_FILE):
            (tmp / CHECKPOINT_POLICY_FILE).write_bytes(
                flax.serialization.to_bytes(checkpoint.policy)
            )
    for name in BEST_FILES:  # see restore_best_policy
        if (Path(run_dir) / name).is_file():
            with naming(tmp / name):
                _link_or_copy(Path(run_dir) / name, tmp / name)
    state = {
        CHECKPOINT_KEY: CHECKPOINT_FORMAT,
        "loop": {
            "step": loop.step,
            "episode": loop.episode,
            "elapsed": loop.elapsed,
            "last_eval": loop.last_eval,
            "best_eval": loop.best_eval,
            "refill_until": loop.refill_until,
            "random_states": RANDOM_STATES_FILE if loop.random_states else None,
            "policy_checkpoint": None if checkpoint is None else _checkpoint_record(checkpoint),
        },
        "reward_state": None
        if reward is None
        else {"values": reward.values, "arrays": REWARD_ARRAYS_FILE if reward.arrays else None},
    }
    with naming(tmp / STATE_FILE):
        (tmp / STATE_FILE).write_text(json.dumps(state))  # last: see run_dir.CHECKPOINT_FILES
    with naming(tmp):
        sync_tree(tmp)


def _checkpoint_record(checkpoint: PolicyCheckpoint) -> dict[str, Any]:
    """What state.json holds of a policy checkpoint: its numbers, and its policy's file."""
    record = dataclasses.asdict(dataclasses.replace(checkpoint, policy=None))
    return {**record, "policy": None if checkpoint.policy is None else CHECKPOINT_POLICY_FILE}


def _read_checkpoint_record(
    record: dict[str, Any] | None,
) -> tuple[PolicyCheckpoint | None, str | None]:
    """A policy checkpoint's numbers from its state.json record (``_checkpoint_record``), and
    the file of its policy (None where it has none yet)."""
    if record is None:
        return None, None
    best, low = record["best_min_return"], record["min_return"]
    checkpoint = PolicyCheckpoint(
        best_min_return=None if best is None else float(best),
        episodes=int(record["episodes"]),
        pending_steps=int(record["pending_steps"]),
        min_return=None if low is None else float(low),
        updates=int(record["updates"]),
    )
    return checkpoint, record["policy"]


BEST_FILES = (BEST_POLICY_FILE, BEST_POLICY_INFO)


def restore_best_policy(run_dir: Path, ckpt_dir: Path | None, best_eval: dict[str, float]) -> None:
    """Put back the best policy that checkpoint ``ckpt_dir`` knows (``best_eval``, its record);
    with no checkpoint (a run starting again from step 0), or none at the checkpoint, remove it.

    An evaluation after the checkpoint may have written a better one. An exact continuation
    writes it again; one that is not exact (from a snapshot, or on other hardware) would keep
    a best policy from a future it discarded, at a step whose metrics row it rewrites.
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
    if best_eval:  # a best evaluation, but no copy of its policy: an older checkpoint
        keep_best_policy_of_older_checkpoint(best_step, best_eval, ckpt_dir, run_dir)
    else:  # no best policy yet at the checkpoint: the files came after it
        for name in BEST_FILES:
            (run_dir / name).unlink(missing_ok=True)


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
    """Read checkpoint directory ``ckpt`` (of any format: ``migrations``); the agent state is
    restored onto ``agent_template`` (its structure and shapes checked), the replay buffer only
    where ``buffer_dims`` (obs, action) is given, and checked against it. A damaged or
    mismatched file is a ValueError naming it."""
    state_path = ckpt / STATE_FILE
    try:
        raw = json.loads(state_path.read_text(encoding="utf-8"))
        state = upgrade_checkpoint_state(raw, {p.name for p in ckpt.iterdir()}, state_path)
        loop_record, reward_record = state["loop"], state["reward_state"]
        loop = LoopState(
            step=int(loop_record["step"]),
            episode=int(loop_record["episode"]),
            elapsed=float(loop_record["elapsed"]),
            last_eval=dict(loop_record["last_eval"]),
            best_eval=dict(loop_record["best_eval"]),
            refill_until=int(loop_record["refill_until"]),
        )
        random_states_file = loop_record["random_states"]
        # Added to format 2 with a default that keeps what older runs did (none).
        policy_checkpoint, policy_file = _read_checkpoint_record(
            loop_record.get("policy_checkpoint")
        )
        if reward_record is not None:
            reward_values, arrays_file = dict(reward_record["values"]), reward_record["arrays"]
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as err:
        raise ValueError(f"{state_path} is not a readable checkpoint state ({err})") from None
    agent_state = load_msgpack(agent_template, ckpt / "agent.msgpack", "agent checkpoint")
    if policy_checkpoint is not None and policy_file is not None:
        policy = load_msgpack(policy_of(agent_template), ckpt / policy_file, "checkpoint policy")
        policy_checkpoint = dataclasses.replace(policy_checkpoint, policy=canonical(policy))
    loop = dataclasses.replace(loop, policy_checkpoint=policy_checkpoint)
    buffer = None
    omitted = not (ckpt / REPLAY_FILE).is_file() and (ckpt / REPLAY_OMITTED).is_file()
    if buffer_dims is not None and not omitted:
        buffer = ReplayBuffer.load(ckpt / REPLAY_FILE)
        if (buffer.obs_dim, buffer.action_dim) != buffer_dims:
            raise ValueError(
                f"{ckpt / REPLAY_FILE}: transitions of (obs, action) dims "
                f"{(buffer.obs_dim, buffer.action_dim)}, this run's config makes {buffer_dims}"
            )
    reward_state = None
    if reward_record is not None:
        arrays = {} if arrays_file is None else load_npz(ckpt / arrays_file, "reward state")
        reward_state = RewardState(reward_values, arrays)
    if random_states_file is not None:
        saved = load_npz(ckpt / random_states_file, "random-phase states")
        states = tuple(saved[k] for k in sorted(saved, key=lambda n: int(n.split("_")[-1])))
        loop = dataclasses.replace(loop, random_states=states)
    return Checkpoint(loop, agent_state, buffer, reward_state, omitted)


def snapshot_run(run_dir: str | Path, out: str | Path) -> Path:
    """A copy of a run small enough to keep in git or move between machines: its config,
    metrics, policies and newest complete checkpoint without the replay buffer (the agent's and
    the reward's state, a few MB; ``REPLAY_OMITTED`` in place of ``replay.npz``). TensorBoard
    events are left out (``metrics.csv`` has every row). ``Trainer.resume`` continues it: the
    buffer is refilled by ``start_steps`` steps of the current policy before updates resume, so
    the continuation is not the exact one the full run directory gives. An on-policy run (sil)
    keeps its buffer, which holds only the batch it has collected since its last update (part
    of its state, at most a batch and an episode: with TRPO's 50,000-step batches up to ~5 MB
    on Hopper, ~100 MB on Humanoid): it continues exactly.

    Raises FileNotFoundError where ``run_dir`` has no complete checkpoint, FileExistsError
    where ``out`` exists, and ValueError where another process is writing the run or ``out``
    lies inside it."""
    run_dir, out = Path(run_dir), Path(out)
    recipe = ALGOS.get(str(read_run_config(run_dir).get("algo")))  # a run dir, or a clear error
    # Read off the record alone: a config this version cannot build is still copied.
    keeps_buffer = recipe is not None and AGENT_PARTS[recipe.agent].on_policy
    with RunLock(run_dir):  # not while a trainer writes it: a checkpoint could be half-replaced
        damaged = newest_checkpoint_is_damaged(run_dir)
        if damaged is not None:
            raise FileNotFoundError(damaged_checkpoint_message(damaged))
        checkpoint = latest_checkpoint(run_dir)
        if checkpoint is None:
            raise FileNotFoundError(f"{run_dir} has no complete checkpoint to snapshot yet")
        check_new_copy_dir(run_dir, out)
        tmp = out.with_name(f".{out.name}.tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        (tmp / CHECKPOINTS_DIR).mkdir(parents=True)
        copy_results(run_dir, tmp)
        target = tmp / CHECKPOINTS_DIR / checkpoint.name
        if keeps_buffer:
            shutil.copytree(checkpoint, target)
        else:
            shutil.copytree(checkpoint, target, ignore=shutil.ignore_patterns(REPLAY_FILE))
            omitted: dict[str, str | int] = {
                "left_out": REPLAY_FILE,
                "from": str(run_dir.resolve() / CHECKPOINTS_DIR),
            }
            if (checkpoint / REPLAY_FILE).is_file():
                omitted["bytes"] = (checkpoint / REPLAY_FILE).stat().st_size
            (target / REPLAY_OMITTED).write_text(json.dumps(omitted))
        tmp.rename(out)
    return out
