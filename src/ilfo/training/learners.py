"""What the training loop does differently for each kind of learner, one strategy a kind.

The registry says which kind an algo's learner is (``Recipe.learner``), and the ``Trainer``
hands the kind's strategy the parts of an episode that differ between kinds:

- ``OffPolicy``: a replay-buffer agent (TD3, DDPG, SAC, TD7) on an episode reward (OOPS, PWIL)
  or the task reward. Uniformly random actions for ``random_steps`` first; after each episode,
  as many updates as steps collected (times ``updates_per_step``).
- ``LearnedReward``: the same, with a reward learned inside the agent's update (GAIfO/DACfO,
  OPOLO, OOPS_adv, f-IRL): the episode's proxy return is its rewards under today's parameters,
  and a reward that learns from fresh episodes of the policy (f-IRL's ``RolloutPlan``) gets
  them when due.
- ``PolicyCheckpoints``: a replay-buffer agent evaluated with TD7's policy checkpoints
  (``agents.policy_checkpoints``): its updates wait while the current policy is assessed on
  its training episodes, then run, and the policy that evaluations use is replaced where the
  current one won.
- ``OnPolicyBatches``: an agent that learns from batches of its own fresh episodes (TRPO, for
  SIL): no random phase, a buffer that holds only the batch under collection, one ``learn``
  when it is full, then the reward's own step where it learns per batch
  (``BatchLearningReward``, SIL's critic).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, Protocol

import jax
import numpy as np

from ilfo.agents import policy_of
from ilfo.agents.base import OnPolicyBatch
from ilfo.agents.policy_checkpoints import CheckpointSchedule, PolicyCheckpoint, canonical
from ilfo.algos import AGENT_PARTS, REWARD_PARTS, LearnedRewardPart, RewardPart
from ilfo.composition.learned import RolloutPlan
from ilfo.training.config import TrainConfig
from ilfo.training.rollout import rollout_policy

if TYPE_CHECKING:  # for annotations only: the trainer imports this module
    from ilfo.training.loop import Trainer

LOGGED = {"critic_loss", "actor_loss", "reward_mean", "reward_loss", "reward_accuracy"}
"""The update and reward metrics that episode rows log (``metrics.METRIC_FIELDS``)."""


class Learner(Protocol):
    """One kind of learner, as the ``Trainer`` drives it."""

    on_policy: bool
    """Whether it learns from its own fresh episodes only: no random phase, a buffer of one
    batch, a policy that changes only when it learns."""

    def buffer_capacity(self, trainer: Trainer) -> int:
        """Transitions the run's buffer holds."""
        ...

    def episode_rewards(self, trainer: Trainer, observations: np.ndarray) -> np.ndarray | None:
        """The rewards (T,) of an episode where this kind computes them; None: the trainer's
        episode reward (or the task reward) gives them."""
        ...

    def learn(
        self, trainer: Trainer, num_steps: int, updating: bool, episode_return: float
    ) -> dict[str, float]:
        """Learn from the episode of ``num_steps`` steps just stored (``updating``: not in the
        random phase nor refilling a snapshot's buffer; ``episode_return``: the sum of the
        rewards it was stored with, the proxy return); returns the metrics to log."""
        ...


class OffPolicy:
    """A replay-buffer agent on an episode reward or the task reward."""

    on_policy = False

    def buffer_capacity(self, trainer: Trainer) -> int:
        capacity = trainer.config.replay_capacity
        if capacity < trainer.horizon:  # else it fails at the first episode's end
            raise ValueError(
                f"replay_capacity (--replay-capacity) must hold an episode: at least the "
                f"horizon, {trainer.horizon}; got {capacity}"
            )
        return capacity

    def episode_rewards(self, trainer: Trainer, observations: np.ndarray) -> np.ndarray | None:
        return None

    def learn(
        self, trainer: Trainer, num_steps: int, updating: bool, episode_return: float
    ) -> dict[str, float]:
        if not updating:
            return {}
        with trainer.hooks.timed("update"):
            trainer.state, metrics = updates(trainer, num_steps * trainer.config.updates_per_step)
        return metrics


class LearnedReward(OffPolicy):
    """A replay-buffer agent composed with a reward learned in its update
    (``composition.learned``, OPOLO)."""

    def __init__(self, functions: Any, rollouts: RolloutPlan | None) -> None:
        self.functions = functions
        """The composed agent's functions (``LearnedRewardAgent``, OPOLO's): ``rewards``, and
        ``learn_from_rollouts`` where the reward learns from rollouts."""
        self.rollouts = rollouts
        """Where the reward learns from fresh episodes of the policy (f-IRL): when, how many."""

    def episode_rewards(self, trainer: Trainer, observations: np.ndarray) -> np.ndarray:
        # The update rewards its batches with the reward's parameters of the time; these
        # (today's, stored but not learned from) are the episode's proxy return.
        return np.asarray(
            self.functions.rewards(trainer.state, observations[:-1], observations[1:])
        )

    def learn(
        self, trainer: Trainer, num_steps: int, updating: bool, episode_return: float
    ) -> dict[str, float]:
        metrics = super().learn(trainer, num_steps, updating, episode_return)
        plan = self.rollouts
        if (
            plan is not None
            and trainer.step // plan.every > (trainer.step - num_steps) // plan.every
        ):
            with trainer.hooks.timed("reward"):
                trajectories = policy_rollouts(trainer, plan.episodes, trainer.step // plan.every)
                trainer.state, learned = self.functions.learn_from_rollouts(  # type: ignore[misc]
                    trainer.state, trajectories
                )
                # Reading the metrics waits for the jitted learning: timed as "reward".
                metrics.update({k: float(v) for k, v in learned.items() if k in LOGGED})
        return metrics


class PolicyCheckpoints(OffPolicy):
    """A replay-buffer agent evaluated with TD7's policy checkpoints: the episode's return
    counts into the assessment under way (``LoopState.policy_checkpoint``); at its end the
    current policy becomes the checkpoint where it won, and then the updates of the
    assessment's steps run, which waited for it."""

    def __init__(self, schedule: CheckpointSchedule) -> None:
        self.schedule = schedule

    def learn(
        self, trainer: Trainer, num_steps: int, updating: bool, episode_return: float
    ) -> dict[str, float]:
        """The assessment's metrics (TensorBoard only) where it ended: ``checkpoint_return``,
        the checkpoint's minimum return, and ``checkpoint_replaced`` (1 or 0)."""
        if not updating:
            return {}
        checkpoint = trainer.loop_state.policy_checkpoint or PolicyCheckpoint()
        current = canonical(policy_of(trainer.state))
        checkpoint, due = checkpoint.end_episode(episode_return, num_steps, current, self.schedule)
        metrics: dict[str, float] = {}
        if due:
            num_updates = due * trainer.config.updates_per_step
            with trainer.hooks.timed("update"):
                trainer.state, metrics = updates(trainer, num_updates)
            checkpoint = checkpoint.updates_done(num_updates, self.schedule)
            assert checkpoint.best_min_return is not None  # set by the first assessment
            metrics["checkpoint_replaced"] = float(checkpoint.policy is current)
            metrics["checkpoint_return"] = checkpoint.best_min_return
        trainer.loop_state = dataclasses.replace(trainer.loop_state, policy_checkpoint=checkpoint)
        return metrics


class OnPolicyBatches:
    """An agent that learns from whole batches of its own fresh episodes (TRPO), with a reward
    that learns once per batch where the registry says so (SIL's critic)."""

    on_policy = True

    def __init__(self, batch_steps: int, reward_learns_per_batch: bool) -> None:
        self.batch_steps = batch_steps
        self.reward_learns_per_batch = reward_learns_per_batch

    def buffer_capacity(self, trainer: Trainer) -> int:
        return self.batch_steps + trainer.horizon  # the batch and the episode that fills it

    def episode_rewards(self, trainer: Trainer, observations: np.ndarray) -> np.ndarray | None:
        return None

    def learn(
        self, trainer: Trainer, num_steps: int, updating: bool, episode_return: float
    ) -> dict[str, float]:
        """One iteration on the episodes collected since the last (all of the buffer's) once
        they make a batch, then the reward's step on the same episodes, and an empty buffer.
        The agent's value loss is logged as ``critic_loss``, its other metrics (TensorBoard
        only) prefixed with ``agent_``."""
        buffer = trainer.buffer
        if buffer.size < self.batch_steps:
            return {}
        with trainer.hooks.timed("update"):
            metrics = self._learn(trainer)
        trainer.buffer = trainer.new_buffer()
        trainer.policy_changed = True
        return metrics

    def _learn(self, trainer: Trainer) -> dict[str, float]:
        buffer, size = trainer.buffer, trainer.buffer.size
        data = jax.tree.map(lambda x: np.asarray(x[:size]), buffer.data)
        episode_end = np.zeros(size, bool)
        for start, length in buffer.episodes.values():
            episode_end[start + length - 1] = True
        batch = OnPolicyBatch(data.obs, data.action, data.reward, episode_end)
        trainer.state, learned = trainer.agent.functions.learn(trainer.state, batch)  # type: ignore[union-attr]
        metrics = {
            "critic_loss" if k == "value_loss" else f"agent_{k}": float(v)
            for k, v in learned.items()
        }
        if self.reward_learns_per_batch:
            metrics.update({k: float(v) for k, v in trainer.rewarder.end_batch().items()})  # type: ignore[union-attr]
        return metrics


def updates(trainer: Trainer, num_updates: int) -> tuple[Any, dict[str, float]]:
    """``num_updates`` agent updates, run as jitted chunks of power-of-two sizes.

    ``update`` compiles once per number of updates; episodes of every length would each
    compile anew, whereas powers of two compile at most log2(horizon * updates_per_step) + 1
    times. Every update draws its keys from the state, so chunks give exactly the updates
    one call would. Metrics are averaged over the chunks that report them (a learned
    reward reports its own only from chunks in which it took steps).
    """
    update = trainer.agent.functions.update  # type: ignore[union-attr]
    state = trainer.state
    totals: dict[str, float] = {}
    weights: dict[str, int] = {}
    remaining, chunk = num_updates, 1 << (num_updates.bit_length() - 1)
    while remaining:
        if chunk <= remaining:
            state, metrics = update(
                state, trainer.buffer.data, trainer.buffer.size, num_updates=chunk
            )
            for name in LOGGED.intersection(metrics):
                totals[name] = totals.get(name, 0.0) + float(metrics[name]) * chunk
                weights[name] = weights.get(name, 0) + chunk
            remaining -= chunk
        chunk >>= 1
    return state, {name: totals[name] / weights[name] for name in totals}


def policy_rollouts(trainer: Trainer, episodes: int, iteration: int) -> np.ndarray:
    """States s_1..s_T (episodes, T, obs_dim) of fresh fixed-horizon episodes of the current
    policy with its exploration, for a reward that learns from them (f-IRL); not stored,
    not counted as steps. A fall that ends an episode early (standard episodes) repeats
    its last state to the horizon, as f-IRL's code does. Their randomness comes from
    (seed, iteration) alone."""
    seed, horizon = trainer.config.seed, trainer.horizon
    rng = np.random.default_rng([seed, iteration, 1])
    key = jax.random.fold_in(jax.random.PRNGKey(seed), 1_000_003 + iteration)
    trajectories = []
    for k in range(episodes):
        rollout = rollout_policy(
            trainer.env,
            trainer.agent,
            trainer.state,
            horizon,
            seed=int(rng.integers(2**31)),
            key=jax.random.fold_in(key, k),
        )
        states = rollout.observations[1:]
        pad = np.repeat(states[-1:], horizon - len(states), axis=0)
        trajectories.append(np.concatenate([states, pad]).astype(np.float32))
    return np.stack(trajectories)


def learner_of(config: TrainConfig, functions: Any) -> Learner:
    """The strategy of ``config``'s algo's kind of learner (``Recipe.learner``), for the agent
    ``functions`` that ``build.make_agent`` made for it."""
    recipe = config.recipe
    part = None if recipe.reward is None else REWARD_PARTS[recipe.reward]
    if recipe.learner == "on_policy":
        learns_per_batch = isinstance(part, RewardPart) and part.learns_per_batch
        return OnPolicyBatches(functions.batch_steps, learns_per_batch)
    if recipe.learner == "learned_reward":
        # What makes a recipe's learner this kind.
        assert recipe.reward is not None and isinstance(part, LearnedRewardPart)
        plan = None if part.rollouts is None else part.rollouts(config.part_config(recipe.reward))
        return LearnedReward(functions, plan)
    checkpoints = AGENT_PARTS[recipe.agent].policy_checkpoints
    schedule = None if checkpoints is None else checkpoints(config.part_config(recipe.agent))
    return OffPolicy() if schedule is None else PolicyCheckpoints(schedule)
