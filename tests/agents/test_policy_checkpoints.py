"""TD7's policy-checkpoint schedule (``ilfo.agents.policy_checkpoints``) as the authors' code
runs it: assessments of one episode early, of up to ``max_episodes`` later, ended early by a
return below the checkpoint's; the checkpoint replaced only by an assessment that never fell
below it; the reset as the updates pass ``early_updates``."""

from __future__ import annotations

import numpy as np
import pytest

from ilfo.agents import Policy
from ilfo.agents.policy_checkpoints import (
    CheckpointSchedule,
    PolicyCheckpoint,
    evaluation_policy,
)

SCHEDULE = CheckpointSchedule(max_episodes=3, early_updates=100, reset_weight=0.5)
OLD, NEW, P1, P2, P3 = (Policy({"w": np.full(2, k)}, np.zeros(3), np.ones(3)) for k in range(5))


def _late() -> PolicyCheckpoint:
    """A checkpoint past the early updates, policy OLD with minimum return 10."""
    return PolicyCheckpoint(policy=OLD, best_min_return=10.0, updates=101)


def test_early_assessments_last_one_episode_and_replace_only_a_lower_checkpoint():
    fresh = PolicyCheckpoint()
    first, due = fresh.end_episode(5.0, 40, P1, SCHEDULE)
    assert due == 40 and first.policy is P1 and first.best_min_return == 5.0
    assert (first.episodes, first.pending_steps, first.min_return) == (0, 0, None)
    first = first.updates_done(40, SCHEDULE)
    lower, due = first.end_episode(4.0, 30, P2, SCHEDULE)
    assert due == 30 and lower.policy is P1 and lower.best_min_return == 5.0
    higher, due = lower.end_episode(6.0, 20, P3, SCHEDULE)
    assert due == 20 and higher.policy is P3 and higher.best_min_return == 6.0


def test_a_late_assessment_defers_its_updates_and_wins_with_its_minimum():
    state, steps = _late(), []
    for k, ret in enumerate([12.0, 11.0, 15.0]):
        state, due = state.end_episode(ret, 10 + k, NEW, SCHEDULE)
        steps.append(due)
    assert steps == [0, 0, 10 + 11 + 12]  # the updates of all three episodes at its end
    assert state.policy is NEW and state.best_min_return == 11.0
    assert (state.episodes, state.pending_steps, state.min_return) == (0, 0, None)


def test_a_late_assessment_ends_at_the_first_return_below_the_checkpoints():
    state, due = _late().end_episode(12.0, 10, NEW, SCHEDULE)
    assert due == 0 and (state.episodes, state.pending_steps, state.min_return) == (1, 10, 12.0)
    state, due = state.end_episode(9.0, 7, NEW, SCHEDULE)
    assert due == 17 and state.policy is OLD and state.best_min_return == 10.0
    assert (state.episodes, state.pending_steps, state.min_return) == (0, 0, None)


def test_the_reset_fires_as_the_updates_pass_early_updates():
    state = PolicyCheckpoint(policy=P1, best_min_return=8.0)
    assert state.max_episodes(SCHEDULE) == 1
    # Up to update number 100 (the authors' check comes before each update): no reset yet.
    at = state.updates_done(100, SCHEDULE)
    assert at.best_min_return == 8.0 and at.max_episodes(SCHEDULE) == 1
    past = at.updates_done(1, SCHEDULE)
    assert past.best_min_return == pytest.approx(4.0) and past.max_episodes(SCHEDULE) == 3
    assert past.updates_done(500, SCHEDULE).best_min_return == past.best_min_return  # once
    across = state.updates_done(250, SCHEDULE)
    assert across.best_min_return == pytest.approx(4.0) and across.updates == 250
    # From the first update where early_updates is 0.
    zero = CheckpointSchedule(3, 0, 0.5)
    assert state.updates_done(1, zero).best_min_return == pytest.approx(4.0)


def test_the_evaluation_policy_is_the_checkpoints_once_there_is_one():
    state = P1
    assert evaluation_policy(None, state).actor_params is state.actor_params
    assert evaluation_policy(PolicyCheckpoint(), state).actor_params is state.actor_params
    checkpoint = PolicyCheckpoint(policy=OLD, best_min_return=1.0)
    assert evaluation_policy(checkpoint, state) is OLD
