"""TD7's policy checkpoints in the training loop (``training.learners.PolicyCheckpoints``): the
updates wait for the assessment's end, the checkpoint policy is what the run evaluates and
saves, a resume mid-assessment equals the uninterrupted run, and an imitation run assesses its
proxy return."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import flax.serialization
import jax
import numpy as np
import pytest

from ilfo.agents import policy_of
from ilfo.evaluate import evaluate_run
from ilfo.training import TrainConfig, Trainer, load_run_policy
from ilfo.training.loop import LoopHooks
from ilfo.training.run_dir import latest_checkpoint
from tiny_run import TINY_RUN, metrics_rows

pytestmark = pytest.mark.integration  # each test trains

SMALL_TD7 = {
    "zs_dim": 16,
    "encoder_hidden": 16,
    "actor_hidden": 16,
    "critic_hidden": 16,
    "target_update_every": 50,
}
# Past the first assessment's 100-odd updates, assessments of up to three episodes, which
# Hopper's positive returns never fall below 1% of the checkpoint's minimum to end early.
LONG_ASSESSMENTS = {
    "checkpoint_early_updates": 0,
    "checkpoint_max_episodes": 3,
    "checkpoint_reset_weight": 0.01,
}


class _Record(LoopHooks):
    """Each episode's step, the agent's update count, the policy checkpoint and the row."""

    def __init__(self) -> None:
        self.episodes: list[tuple[int, int, Any, dict[str, Any]]] = []
        self.proxy_returns: list[float] = []

    def episode_rewarded(self, trainer: Trainer, output: Any) -> None:
        self.proxy_returns.append(float(np.sum(output.rewards)))

    def episode_ended(self, trainer: Trainer, row: dict[str, Any]) -> None:
        checkpoint = trainer.loop_state.policy_checkpoint
        self.episodes.append((trainer.step, int(trainer.state.step), checkpoint, dict(row)))


def _same(a: Any, b: Any) -> bool:
    """Whether two policies hold the same arrays."""
    leaves_a, leaves_b = jax.tree.leaves(a), jax.tree.leaves(b)
    return jax.tree.structure(a) == jax.tree.structure(b) and all(
        np.array_equal(x, y) for x, y in zip(leaves_a, leaves_b, strict=True)
    )


def _train(run: Path, hooks: LoopHooks | None = None, **overrides: Any) -> Trainer:
    settings = {**TINY_RUN, "steps": 600, **overrides}
    if settings["algo"] == "td7":
        settings.pop("demos")
    trainer = Trainer(TrainConfig(**settings), run, progress=False, hooks=hooks)
    trainer.train()
    return trainer


def test_updates_wait_for_the_assessment_and_a_resume_mid_assessment_is_exact(tmp_path):
    record = _Record()
    td7 = {"algo": "td7", "td7": {**SMALL_TD7, **LONG_ASSESSMENTS}}
    full = _train(tmp_path / "full", record, **td7)
    random_end = next(step for step, *_ in record.episodes if step >= TINY_RUN["start_steps"])
    mid = []
    for step, updates, checkpoint, row in record.episodes:
        if step <= random_end:
            continue
        # Every update of an ended assessment's steps has run, none of the one under way's.
        assert updates == checkpoint.updates == step - random_end - checkpoint.pending_steps
        assert ("critic_loss" in row) == (checkpoint.episodes == 0)
        if checkpoint.episodes:
            mid.append(step)
    assert mid, "no episode inside an assessment"
    final = full.loop_state.policy_checkpoint
    run = tmp_path / "full"
    # The run evaluates and saves the checkpoint policy, not the one its updates changed since.
    saved = (run / "policy.msgpack").read_bytes()
    assert saved == flax.serialization.to_bytes(final.policy)
    assert saved != flax.serialization.to_bytes(policy_of(full.state))
    assert _same(load_run_policy(run, "latest").policy, final.policy)
    assert _same(load_run_policy(run, "final").policy, final.policy)
    last = metrics_rows(run)[-1]
    if last["eval_score"]:  # the evaluation after the last episode's assessment
        assert evaluate_run(run, episodes=1)["score_mean"] == pytest.approx(
            float(last["eval_score"]), abs=1e-3
        )

    # Stopped inside an assessment, with a checkpoint policy: its state and policy checkpointed.
    stop = next(step for step in mid if step >= 300)
    stopped = _train(tmp_path / "resumed", steps=stop, **td7)
    assert stopped.step == stop
    state = json.loads((latest_checkpoint(stopped.run_dir) / "state.json").read_text())
    kept = state["loop"]["policy_checkpoint"]
    assert kept["pending_steps"] > 0 and kept["policy"] == "checkpoint_policy.msgpack"
    resumed = Trainer.resume(tmp_path / "resumed", progress=False, steps=600)
    before, after = stopped.loop_state.policy_checkpoint, resumed.loop_state.policy_checkpoint
    assert dataclasses.replace(after, policy=None) == dataclasses.replace(before, policy=None)
    assert _same(after.policy, before.policy)
    assert metrics_rows(resumed.train()) == metrics_rows(run)
    for name in ("policy.msgpack", "best_policy.msgpack"):
        assert (tmp_path / "resumed" / name).read_bytes() == (run / name).read_bytes(), name


def test_an_imitation_run_assesses_the_proxy_return_and_off_updates_every_episode(tmp_path):
    record = _Record()
    oops_td7 = {"algo": "oops-td7", "steps": 300}
    _train(tmp_path / "on", record, td7=SMALL_TD7, **oops_td7)
    (_, _, checkpoint, row), proxy = record.episodes[-1], record.proxy_returns[-1]
    # The first assessment (its one episode) always wins: its minimum is that episode's
    # return under the OOPS reward, which the learner sees, not the task's.
    assert checkpoint.best_min_return == proxy
    assert checkpoint.policy is not None and checkpoint.episodes == 0
    assert abs(proxy - float(row["train_task_return"])) > 1.0

    off = _Record()
    trainer = _train(
        tmp_path / "off", off, td7={**SMALL_TD7, "policy_checkpoints": False}, **oops_td7
    )
    assert all(checkpoint is None for _, _, checkpoint, _ in off.episodes)
    assert trainer.loop_state.policy_checkpoint is None
    assert not (latest_checkpoint(trainer.run_dir) / "checkpoint_policy.msgpack").exists()
