"""TD7's policy checkpoints (Fujimoto et al., NeurIPS 2023, "For SALE", its policy
checkpoints; the authors' ``maybe_train_and_checkpoint`` in sfujim/TD7) as bookkeeping between
episodes, without the loop.

A run evaluates a *checkpoint* policy rather than the policy as trained, which may have just
taken a bad step. The current policy is assessed on its own training episodes while its
updates wait; the assessment ends

- early, at the first episode whose return falls below the checkpoint's minimum (the current
  policy cannot beat it), the checkpoint staying;
- or after its last episode (one while the agent has run at most ``early_updates`` updates,
  ``max_episodes`` after), the current policy then replacing the checkpoint, its minimum
  return over the assessment the new one to beat (at least as high: it never fell below).

Then the waiting updates run, as many as the assessment's steps (times the run's updates per
step), and the next assessment starts. As the updates pass ``early_updates`` the checkpoint's
minimum is multiplied by ``reset_weight`` (0.9), since one episode's return is a lenient bar
beside the minimum of many. Returns are what the agent learns from: the task return on the
task reward, the imitation reward's sum (the proxy return) under an imitation reward, which
never sees the task's.

The training loop keeps a ``PolicyCheckpoint`` in its state between episodes
(``training.checkpoint.LoopState``) and drives it (``training.learners.PolicyCheckpoints``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, NamedTuple

import jax

from ilfo.agents._common import Policy, policy_of

__all__ = ["CheckpointSchedule", "PolicyCheckpoint", "canonical", "evaluation_policy"]


class CheckpointSchedule(NamedTuple):
    """How long assessments last and when they lengthen (``TD7Config``'s ``checkpoint_*``)."""

    max_episodes: int
    """Episodes an assessment lasts at most once ``early_updates`` updates have run."""
    early_updates: int
    """Updates during which an assessment lasts one episode."""
    reset_weight: float
    """The checkpoint's minimum return is multiplied by it as the updates pass
    ``early_updates``."""


@dataclass(frozen=True)
class PolicyCheckpoint:
    """The checkpoint policy and the assessment under way, at an episode boundary. Replaced,
    never changed in place."""

    policy: Policy | None = None
    """The checkpoint policy, which evaluations use; None before the first assessment ends
    (no update has run yet: the current policy is the first one)."""
    best_min_return: float | None = None
    """The minimum return of the checkpoint's assessment (scaled once by ``reset_weight``);
    None before the first."""
    episodes: int = 0
    """Episodes of the assessment under way."""
    pending_steps: int = 0
    """Their steps, whose updates wait for the assessment's end."""
    min_return: float | None = None
    """The lowest return of the assessment's episodes; None before its first."""
    updates: int = 0
    """Updates run after assessments so far."""

    def max_episodes(self, schedule: CheckpointSchedule) -> int:
        """Episodes the assessment under way lasts at most."""
        return schedule.max_episodes if self.updates > schedule.early_updates else 1

    def end_episode(
        self, episode_return: float, num_steps: int, current: Policy, schedule: CheckpointSchedule
    ) -> tuple[PolicyCheckpoint, int]:
        """Count an episode of ``num_steps`` steps of the ``current`` policy into the
        assessment. Returns the new state and the steps whose updates are due now: 0 while the
        assessment goes on, else all of its steps (the state is then the next assessment's,
        with ``current`` as the checkpoint where it won)."""
        low = episode_return if self.min_return is None else min(self.min_return, episode_return)
        episodes, steps = self.episodes + 1, self.pending_steps + num_steps
        beaten = self.best_min_return is not None and low < self.best_min_return
        if not beaten and episodes < self.max_episodes(schedule):
            going_on = dataclasses.replace(
                self, episodes=episodes, pending_steps=steps, min_return=low
            )
            return going_on, 0
        done = dataclasses.replace(self, episodes=0, pending_steps=0, min_return=None)
        if not beaten:
            done = dataclasses.replace(done, policy=current, best_min_return=low)
        return done, steps

    def updates_done(self, num_updates: int, schedule: CheckpointSchedule) -> PolicyCheckpoint:
        """Count ``num_updates`` updates run after an assessment; where they pass
        ``early_updates``, the checkpoint's minimum return is scaled by ``reset_weight``."""
        before, after = self.updates, self.updates + num_updates
        best = self.best_min_return
        # The authors' check runs before each update: it fires at update number early_updates.
        if before <= schedule.early_updates < after and best is not None:
            best *= schedule.reset_weight
        return dataclasses.replace(self, updates=after, best_min_return=best)


def evaluation_policy(checkpoint: PolicyCheckpoint | None, state: Any) -> Policy:
    """The policy a run evaluates and saves: the checkpoint's where it has one, else that of
    the agent's ``state`` (an agent without policy checkpoints, or before the first)."""
    if checkpoint is not None and checkpoint.policy is not None:
        return checkpoint.policy
    return policy_of(state)


def canonical(policy: Policy) -> Policy:
    """``policy`` with its dicts in sorted key order (the same arrays): a checkpoint policy
    taken from the agent's state (in the order its update left) and one read back from a
    file (in its template's) then save as the same bytes, so that a resumed run's policy files
    are the uninterrupted run's."""
    return jax.tree.map(lambda leaf: leaf, policy)
