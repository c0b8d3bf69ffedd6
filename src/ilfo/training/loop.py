"""The training loop: collect an episode, reward it, store it, update the agent, evaluate.

This is the one place where an episode reward and an agent meet (neither imports the other). It
follows the paper's code (docs/reproduction.md): uniformly random actions for ``start_steps``,
then one episode at a time with the policy frozen; at the end of each episode its rewards are
computed and the episode enters the replay buffer, then as many updates run as steps were
collected (``updates_per_step`` times as many; jitted calls). Every ``eval_every`` steps,
deterministic fixed-horizon episodes are scored. ``LoopHooks`` observe it (timing, logging)
without changing it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
import warnings
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ilfo.agents import policy_of
from ilfo.agents.policy_checkpoints import evaluation_policy
from ilfo.files import write_bytes_atomic, write_json_atomic
from ilfo.replay import ReplayBuffer
from ilfo.rewards import RewardOutput
from ilfo.training.build import (
    load_demo_set,
    make_agent,
    make_envs,
    make_reward,
    network_normalizer,
)
from ilfo.training.checkpoint import (
    Checkpoint,
    LoopState,
    load_checkpoint,
    restore_best_policy,
    save_checkpoint,
)
from ilfo.training.config import TrainConfig, config_from_dict
from ilfo.training.console import bar_postfix, progress_bar, stop_requests
from ilfo.training.learners import Learner, learner_of
from ilfo.training.metrics import MetricsLog, truncate_metrics
from ilfo.training.migrations import config_record, read_run_config, upgrade_run_dir
from ilfo.training.plots import plot_runs
from ilfo.training.resources import check_memory
from ilfo.training.rollout import (
    agent_observation,
    agent_observations,
    env_action,
    evaluation_seeds,
    score_policy,
)
from ilfo.training.run_dir import (
    BEST_POLICY_FILE,
    BEST_POLICY_INFO,
    CHECKPOINTS_DIR,
    CONFIG_FILE,
    DEMOS_RECORD_FILE,
    FINAL_POLICY_FILE,
    RunLock,
    damaged_checkpoint_message,
    fault_point,
    latest_checkpoint,
    newest_checkpoint_is_damaged,
    read_demos_record,
    remove_incomplete_checkpoints,
    results_past_first_checkpoint,
)

_NOTHING = contextlib.nullcontext()


class LoopHooks:
    """Observers of the training loop (``Trainer(..., hooks=...)``): override what you need;
    every default does nothing. They see the trainer but must not change it."""

    def timed(self, piece: str) -> AbstractContextManager[Any]:
        """A context around each piece of the loop's work: ``env`` (one environment step),
        ``act`` (one exploratory action, synchronised), ``reward`` (an episode's rewards),
        ``replay`` (an episode into the buffer: an asynchronous write), ``update`` (an
        episode's agent updates, synchronised) and ``evaluate``."""
        return _NOTHING

    def episode_started(self, trainer: Trainer) -> None:
        """Before an episode's first step."""

    def episode_rewarded(self, trainer: Trainer, output: RewardOutput) -> None:
        """After the episode reward has rewarded an episode (imitation algos only)."""

    def episode_ended(self, trainer: Trainer, row: dict[str, Any]) -> None:
        """After an episode's row was written to the metrics (before any checkpoint)."""


class Trainer:
    """A training run in a run directory; ``Trainer.resume(run_dir)`` continues one."""

    def __init__(
        self,
        config: TrainConfig,
        run_dir: str | Path,
        *,
        progress: bool = True,
        hooks: LoopHooks | None = None,
    ) -> None:
        self.config = config
        self.run_dir = Path(run_dir)
        self.progress = progress
        self.hooks = hooks or LoopHooks()
        self.resume_command = f"ilfo train --resume {self.run_dir}"
        """What the interrupt message tells the user to run to continue (the CLI may change it)."""
        self.env, self.eval_env, env = make_envs(config)
        self.horizon, self.obs_dim = env.horizon, env.obs_dim
        self.action_dim, self.max_action = env.action_dim, env.max_action
        demos = load_demo_set(config, env.obs_dim)
        # Before anything large is allocated (replay, networks, an OT reward's matrices).
        lengths = [len(d) - 1 for d in demos.observations]
        check_memory(config, env.obs_dim, env.action_dim, env.horizon, lengths)
        self.demos, self.demo_return = demos.observations, demos.mean_return
        self.distance_probe = demos.distance_probe
        self.demo_source = demos.source
        self.rewarder = make_reward(config, self.demos)
        self.unconverged_rewards = 0  # episodes whose coupling missed its tolerance
        self.agent = make_agent(config, env, self.demos)
        self.learner: Learner = learner_of(config, self.agent.functions)
        """What this kind of learner does differently in the loop (``training.learners``)."""
        self.state = self.agent.functions.init(config.seed)
        self.buffer = self.new_buffer()
        self.loop_state = LoopState()
        """The loop's own state (counters, evaluations, random-phase states), which a
        checkpoint keeps whole; replaced as the loop goes, never changed in place."""
        self._lock = RunLock(self.run_dir)  # held while this trainer writes the run directory
        self._resumed = False  # set by ``resume``: the run directory holds this run already
        self._metrics: MetricsLog | None = None  # opened by ``train``
        # Whether the policy may differ from the one last evaluated: always, for an off-policy
        # agent; for an on-policy one, after each ``learn`` (and after a resume: recomputing
        # the last evaluation gives the same numbers).
        self.policy_changed = True
        self._bar: Any = None  # the progress bar while ``train`` runs: ``_collect`` moves it

    @property
    def step(self) -> int:
        """Environment steps done (``loop_state``)."""
        return self.loop_state.step

    @property
    def episode(self) -> int:
        """Episodes done (``loop_state``)."""
        return self.loop_state.episode

    @property
    def elapsed(self) -> float:
        """Wall-clock seconds of training so far (``loop_state``)."""
        return self.loop_state.elapsed

    @property
    def last_eval(self) -> dict[str, float]:
        """The last evaluation's metrics, empty before the first (``loop_state``)."""
        return self.loop_state.last_eval

    @property
    def best_eval(self) -> dict[str, float]:
        """The best evaluation so far by ``config.best_by``, with its step (``loop_state``)."""
        return self.loop_state.best_eval

    @property
    def refill_until(self) -> int:
        """Updates wait until this step (a run continued from a snapshot refills its buffer)."""
        return self.loop_state.refill_until

    def _advance(self, **changes: Any) -> None:
        """Replace fields of ``loop_state``."""
        self.loop_state = dataclasses.replace(self.loop_state, **changes)

    def checkpoint_plan(self) -> str:
        """Where and when this run checkpoints, in words (the CLI prints it at the start)."""
        cfg = self.config
        clock = f" and every {cfg.checkpoint_minutes:g} min" if cfg.checkpoint_minutes else ""
        return (
            f"checkpoints: {self.run_dir / CHECKPOINTS_DIR}, every {cfg.checkpoint_every:,} "
            f"steps{clock}, at the end and on Ctrl-C"
        )

    # ----------------------------------------------------------------------------- the loop
    def train(self) -> Path:
        """Run until ``config.steps``; returns the run directory."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self._lock.acquire()  # one writer per run directory (RunDirInUse otherwise)
        try:
            if not self._resumed:
                self._start_run_dir()
            self._metrics = MetricsLog(self.run_dir, self.step if self._resumed else None)
            self._loop()
            self._metrics.close()
            self._save_policy(FINAL_POLICY_FILE)
            if self.last_eval:  # an evaluation was logged: there is a curve to draw
                plot_runs([self.run_dir], self.run_dir / "learning_curve.png")
        finally:
            if self._metrics is not None:
                self._metrics.close()
            self._lock.release()
        return self.run_dir

    def _start_run_dir(self) -> None:
        config_path = self.run_dir / CONFIG_FILE
        if config_path.exists():
            raise ValueError(
                f"{self.run_dir} holds a run already: continue it with "
                "Trainer.resume (ilfo train --resume), or choose another directory"
            )
        resolved = self.config.resolved(self.horizon)  # every setting, as the run uses it
        if resolved.demos is not None:  # absolute: eval and resume work from any directory
            resolved = dataclasses.replace(resolved, demos=str(Path(resolved.demos).resolve()))
        # The demos record first: a run directory with a config.json has it (migrations).
        if self.demo_source is not None:
            write_json_atomic(self.run_dir / DEMOS_RECORD_FILE, self.demo_source.as_record(0))
        write_json_atomic(config_path, config_record(dataclasses.asdict(resolved)))

    def _check_demos_record(self) -> None:
        """On resume: warn where the demo file no longer holds what the run started on (an
        expert re-exported since)."""
        source = self.demo_source
        record = None if source is None else read_demos_record(self.run_dir)
        if source is None or record is None or record.get("sha256") == source.sha256:
            return
        warnings.warn(
            f"{source.path} is not the demo file this run started on "
            f"({record.get('path')}, sha256 {str(record.get('sha256'))[:12]}..., recorded "
            f"in {self.run_dir / DEMOS_RECORD_FILE}): the run continues on its demos, whose "
            f"mean return {source.mean_return:.6g} now divides the scores (it was "
            f"{record.get('mean_return')}); its report cell is no longer set beside the "
            "paper's",
            stacklevel=3,
        )

    def _loop(self) -> None:
        """Episodes until ``config.steps``, checkpointing by steps and by the clock; the first
        Ctrl-C (or SIGTERM) stops at the next episode boundary with a checkpoint."""
        cfg = self.config
        bar = self._bar = progress_bar(cfg.steps, self.step, self.progress)
        start_wall = time.perf_counter() - self.elapsed
        next_checkpoint = (self.step // cfg.checkpoint_every + 1) * cfg.checkpoint_every
        # The step of the newest checkpoint; None before the first (a second Ctrl-C can come
        # before any).
        last_checkpoint: int | None = self.step if latest_checkpoint(self.run_dir) else None
        last_checkpoint_time = time.monotonic()
        checkpoint_seconds = 60.0 * cfg.checkpoint_minutes or math.inf
        try:
            with stop_requests() as stop:
                while self.step < cfg.steps:
                    t0 = time.perf_counter()
                    row = self._episode()
                    self._advance(elapsed=time.perf_counter() - start_wall)
                    row["wall_time"] = round(self.elapsed, 3)
                    row["steps_per_s"] = round(row.pop("_steps") / (time.perf_counter() - t0), 1)
                    self._metrics.write(row)  # type: ignore[union-attr]
                    self.hooks.episode_ended(self, row)
                    fault_point("episode_end")
                    bar.update(self.step - bar.n)
                    bar.set_postfix(bar_postfix(row, self.last_eval), refresh=False)
                    if (
                        self.step >= next_checkpoint
                        or self.step >= cfg.steps
                        or stop.requested
                        or time.monotonic() - last_checkpoint_time >= checkpoint_seconds
                    ):
                        self.save_checkpoint()
                        last_checkpoint, last_checkpoint_time = self.step, time.monotonic()
                        next_checkpoint = (self.step // cfg.checkpoint_every + 1) * (
                            cfg.checkpoint_every
                        )
                    if stop.requested and self.step < cfg.steps:
                        raise KeyboardInterrupt
        except KeyboardInterrupt:
            # A stop request is honoured at an episode boundary, just checkpointed; a second
            # Ctrl-C quits at once, and the last checkpoint (consistent by construction) stays.
            bar.close()
            where = (
                "before the first checkpoint (it starts again from step 0)"
                if last_checkpoint is None
                else f"checkpoint at step {last_checkpoint}"
            )
            print(f"\ninterrupted: {where}; continue with `{self.resume_command}`")
            raise
        bar.close()

    def _report_unconverged(self, output: RewardOutput) -> None:
        """Say once per trainer that a coupling missed its tolerance (its rewards are used as
        they are); later ones are counted in ``unconverged_rewards``. At the paper's settings
        Sinkhorn converges in tens of iterations, so one that does not is worth a look."""
        self.unconverged_rewards += 1
        if self.unconverged_rewards == 1:
            coupling = output.coupling
            solver = coupling.solver
            advice = " A larger max_iter or reg converges sooner." if solver == "sinkhorn" else ""
            warnings.warn(
                f"episode {self.episode}: the reward's {solver} coupling did not "
                f"converge ({coupling.iterations} iterations, marginal error "
                f"{coupling.marginal_error:.3g}); its rewards are used as they are. Later "
                f"ones are not reported (Trainer.unconverged_rewards counts them).{advice}",
                stacklevel=2,
            )

    def _episode(self) -> dict[str, Any]:
        """Collect, reward, store and learn from one episode; evaluate when due."""
        cfg = self.config
        # An on-policy agent collects with its own policy from the start (SIL's code).
        random_phase = self.step < cfg.random_steps and not self.learner.on_policy
        refilling = self.step < self.refill_until
        if not random_phase and not bool(self.state.normalizer_set):
            self._fit_normalizer()
        self.hooks.episode_started(self)
        observations, actions, task_rewards, env_terminated, terminated = self._collect(
            random_phase
        )
        num_steps = len(actions)
        self._advance(step=self.step + num_steps, episode=self.episode + 1)

        rewards = self._episode_rewards(observations, task_rewards, env_terminated)
        agent_obs = agent_observations(observations, self.horizon, self.agent.time_feature)
        # The paper's code cuts bootstrapping at the end of a fixed-horizon episode (its time
        # feature is then 0); standard mode bootstraps through truncation only.
        done = terminated or (cfg.uses_fixed_horizon and num_steps == self.horizon)
        with self.hooks.timed("replay"):
            self.buffer.add_episode(agent_obs, np.asarray(actions), rewards, terminated=done)
        if random_phase:
            self._advance(random_states=(*self.loop_state.random_states, observations[:-1]))

        row: dict[str, Any] = {
            "step": self.step,
            "episode": self.episode,
            "proxy_return": round(float(np.sum(rewards)), 4),
            "train_task_return": round(float(np.sum(task_rewards)), 4),
            "_steps": num_steps,
        }
        updating = not random_phase and not refilling
        metrics = self.learner.learn(self, num_steps, updating, float(np.sum(rewards)))
        row.update({name: round(value, 5) for name, value in metrics.items()})
        if self.step // cfg.eval_every > (self.step - num_steps) // cfg.eval_every:
            # An on-policy agent's policy changes only when it learns, and evaluation is
            # deterministic (fixed seeds): between two learns it would score the same again.
            if self.policy_changed or not self.last_eval:
                with self.hooks.timed("evaluate"):
                    self._advance(last_eval=self.evaluate())
                self.policy_changed = not self.learner.on_policy
            row.update(self.last_eval)
            self._keep_best()
        return row

    def _episode_rewards(
        self, observations: np.ndarray, task_rewards: list, env_terminated: list
    ) -> np.ndarray:
        """The episode's rewards: the learner's own (a learned reward's), else the episode
        reward's, else the task reward (zeroed on reported terminations in fixed-horizon runs,
        whose episodes go on)."""
        with self.hooks.timed("reward"):
            rewards = self.learner.episode_rewards(self, observations)
            if rewards is not None or self.rewarder is None:
                output = None
            else:
                output = self.rewarder(observations)
        if rewards is not None:
            return rewards
        if output is None:
            rewards = np.asarray(task_rewards)
            return (
                np.where(env_terminated, 0.0, rewards)
                if self.config.uses_fixed_horizon
                else rewards
            )
        self.hooks.episode_rewarded(self, output)
        if not output.coupling.converged:
            self._report_unconverged(output)
        return output.rewards

    def _collect(self, random_phase: bool) -> tuple[np.ndarray, list, list, list, bool]:
        """One episode of the frozen policy (uniform actions in the random phase): its
        observations (T + 1, d), actions, task rewards, reported terminations, and whether it
        ended by termination. Its randomness comes from (seed, episode index) alone."""
        cfg, funcs, timed = self.config, self.agent.functions, self.hooks.timed
        rng = np.random.default_rng([cfg.seed, self.episode])
        obs, _ = self.env.reset(seed=int(rng.integers(2**31)))
        observations, actions, task_rewards, env_terminated = [obs], [], [], []
        explore_key = jax.random.fold_in(jax.random.PRNGKey(cfg.seed), self.episode)
        # All of the episode's exploration keys at once, as numpy: one dispatch, not one a step.
        step_keys = np.asarray(jax.random.split(explore_key, self.horizon))
        policy = policy_of(self.state)  # frozen for the episode; few leaves: fast dispatch
        time_feature, terminated = self.agent.time_feature, False
        # The bar moves ten times an episode as it is collected (the updates follow it as
        # compiled chunks, which it waits for); the loop catches it up at the episode's end.
        bar_every = max(1, self.horizon // 10)
        for t in range(self.horizon):
            if t and t % bar_every == 0 and self._bar is not None:
                self._bar.update(bar_every)
            if random_phase:
                action = rng.uniform(-self.max_action, self.max_action, self.action_dim)
            else:
                agent_obs = agent_observation(obs, t, self.horizon, time_feature)
                with timed("act"):
                    action = np.asarray(funcs.act(policy, agent_obs, step_keys[t]), np.float64)
            with timed("env"):
                to_env = env_action(action, self.max_action)
                obs, reward, terminated, truncated, info = self.env.step(to_env)
            observations.append(obs)
            actions.append(action)
            task_rewards.append(float(reward))
            env_terminated.append(bool(info.get("env_terminated", terminated)))
            if terminated or truncated:
                break
        return np.asarray(observations), actions, task_rewards, env_terminated, terminated

    def new_buffer(self) -> ReplayBuffer:
        """An empty buffer of the capacity this kind of learner keeps: the replay buffer of
        ``replay_capacity`` transitions, or an on-policy agent's batch under collection."""
        obs_dim = self.obs_dim + int(self.agent.time_feature)
        return ReplayBuffer(self.learner.buffer_capacity(self), obs_dim, self.action_dim)

    def _fit_normalizer(self) -> None:
        """Fix the networks' normaliser once, when the policy takes over: see
        ``build.network_normalizer``. An on-policy agent has no random phase: its normaliser
        is the demos' states' (mean, std floored as there)."""
        demo_states = [d[:-1] for d in self.demos]
        if self.learner.on_policy and demo_states:
            states, expert = np.concatenate(demo_states), []
        elif self.loop_state.random_states:
            states, expert = np.concatenate(self.loop_state.random_states), demo_states
        else:
            states, expert = np.zeros((1, self.obs_dim)), demo_states
        mean, std = network_normalizer(states, expert)
        if self.agent.time_feature:  # the time feature is already in [0, 1]
            mean, std = np.append(mean, 0.0), np.append(std, 1.0)
        self.state = self.agent.functions.set_normalizer(self.state, mean, std)
        self._advance(random_states=())

    # ------------------------------------------------------------------------ evaluation
    def evaluate(self) -> dict[str, float]:
        """Deterministic fixed-horizon episodes of the evaluated policy (TD7's checkpoint
        policy where it has one): both scores, normalised, and OT distance."""
        seeds = evaluation_seeds(self.config.seed, self.config.eval_episodes)
        policy = evaluation_policy(self.loop_state.policy_checkpoint, self.state)
        scored = score_policy(
            self.eval_env, self.agent, policy, self.horizon, seeds, self.distance_probe
        )
        out = {
            "eval_score": round(float(np.mean(scored.scores)), 3),
            "eval_return": round(float(np.mean(scored.returns)), 3),
        }
        if not math.isnan(self.demo_return):
            out["eval_score_norm"] = round(out["eval_score"] / self.demo_return, 4)
            out["eval_return_norm"] = round(out["eval_return"] / self.demo_return, 4)
        if len(scored.distances):
            out["eval_ot_distance"] = round(float(np.mean(scored.distances)), 5)
        return out

    def _keep_best(self) -> None:
        """Save the policy as best_policy.msgpack if the last evaluation beats the best one."""
        best_key = f"eval_{self.config.best_by}"
        if self.last_eval[best_key] > self.best_eval.get(best_key, -math.inf):
            self._advance(best_eval={"step": self.step, **self.last_eval})
            self._save_policy(BEST_POLICY_FILE)
            info = {**self.best_eval, "elapsed": self.elapsed}
            write_json_atomic(self.run_dir / BEST_POLICY_INFO, info)

    # ------------------------------------------------------------------ files and resume
    def save_checkpoint(self) -> Path:
        """Write the run's whole state at this episode boundary (``checkpoint.save_checkpoint``:
        atomic; a kill at any moment leaves a complete checkpoint). The metrics are flushed to
        the disk first, so that metrics.csv and TensorBoard's events hold every row up to it."""
        if self._metrics is not None:
            self._metrics.flush()
        reward_state = None if self.rewarder is None else self.rewarder.state()
        ckpt = Checkpoint(self.loop_state, self.state, self.buffer, reward_state)
        return save_checkpoint(self.run_dir, ckpt)

    @classmethod
    def resume(
        cls,
        run_dir: str | Path,
        *,
        progress: bool = True,
        steps: int | None = None,
        hooks: LoopHooks | None = None,
    ) -> Trainer:
        """Reload a run from its newest checkpoint to continue it; ``steps`` may change its
        budget, down to the steps already done.

        Changes files only once the checkpoint has loaded: rows of metrics.csv logged after the
        checkpoint are dropped when training starts (they will be logged again, as
        TensorBoard's are hidden), the best policy is the checkpoint's again
        (``checkpoint.restore_best_policy``), what a killed checkpoint write left is removed,
        a run directory of an older format is brought to today's
        (``migrations.upgrade_run_dir``) and a new ``steps`` is written to config.json. A run
        killed before its first checkpoint starts again from step 0 (with a warning); one with
        no complete checkpoint that holds what only a run past its first writes
        (``run_dir.results_past_first_checkpoint``: a finished run whose checkpoints were
        removed) is refused with a ValueError, its files untouched. The returned trainer owns
        the run directory (``RunDirInUse`` if another process does) until its ``train``
        returns.
        """
        run_dir = Path(run_dir)
        raw = read_run_config(run_dir)
        if steps is not None:
            raw = {**raw, "steps": steps}
        lock = RunLock(run_dir).acquire()
        try:
            config = config_from_dict(raw, run_dir / CONFIG_FILE)
            trainer = cls(config, run_dir, progress=progress, hooks=hooks)
            checkpoint = latest_checkpoint(run_dir)
            damaged = newest_checkpoint_is_damaged(run_dir)
            if damaged is not None:
                raise FileNotFoundError(damaged_checkpoint_message(damaged))
            if checkpoint is None:
                results = results_past_first_checkpoint(run_dir, config)
                if results is not None:
                    raise ValueError(
                        f"{run_dir} has no complete checkpoint but holds the results of a run "
                        f"past its first one ({results}; its {CHECKPOINTS_DIR}/ removed?): "
                        "nothing can be resumed, and starting again from step 0 would delete "
                        "them; to train it again, start a new run from its config: ilfo train "
                        f"--config {run_dir / CONFIG_FILE}"
                    )
                warnings.warn(
                    f"{run_dir} has no complete checkpoint yet: the run starts again from step 0",
                    stacklevel=2,
                )
            else:
                trainer._restore(checkpoint)
            # Its last episode may have run past the budget (episodes end whole): that is no
            # shortening unless a smaller budget was asked for.
            if steps is not None and trainer.step > steps:
                raise ValueError(
                    f"{run_dir} has done {trainer.step} steps already (its checkpoint): --steps "
                    f"{steps} would shorten it; pass at least {trainer.step}"
                )
            remove_incomplete_checkpoints(run_dir)
            source = trainer.demo_source
            upgrade_run_dir(run_dir, None if source is None else source.as_record(trainer.step))
            restore_best_policy(run_dir, checkpoint, trainer.best_eval)
            if trainer.step < config.steps:  # a final policy of a shorter budget is no longer
                (run_dir / FINAL_POLICY_FILE).unlink(missing_ok=True)  # the run's final one
            if steps is not None:
                write_json_atomic(run_dir / CONFIG_FILE, config_record(raw))
            trainer._check_demos_record()
            truncate_metrics(run_dir / "metrics.csv", trainer.step)
        except BaseException:
            lock.release()
            raise
        trainer._lock, trainer._resumed = lock, True
        return trainer

    def _restore(self, path: Path) -> None:
        """Continue from checkpoint directory ``path`` (``checkpoint.load_checkpoint``); to read
        a run without continuing it, see ``policy.load_run_policy``."""
        dims = (self.buffer.obs_dim, self.buffer.action_dim)
        ckpt = load_checkpoint(path, self.state, dims)
        loop = ckpt.loop
        if ckpt.buffer is None:  # a snapshot's checkpoint (checkpoint.snapshot_run)
            if self.learner.on_policy:
                raise ValueError(
                    f"{path} has no replay buffer (a snapshot taken before ilfo kept an "
                    "on-policy run's): an on-policy run keeps its pending batch there and "
                    "cannot continue without it; continue the full run directory instead"
                )
            loop = dataclasses.replace(loop, refill_until=loop.step + self.config.random_steps)
            warnings.warn(
                f"{path} has no replay buffer (a snapshot of the run): the buffer is refilled "
                f"by {self.config.random_steps:,} steps of the current policy before updates "
                "resume; the run continues, but not exactly as the uninterrupted one would",
                stacklevel=3,
            )
        else:
            self.buffer = ckpt.buffer
        self.state, self.loop_state = ckpt.agent_state, loop
        if ckpt.reward_state is not None and self.rewarder is not None:
            self.rewarder.load_state(ckpt.reward_state)

    def _save_policy(self, name: str) -> None:
        """The evaluated policy alone (actor parameters and observation normaliser; TD7's
        checkpoint policy where it has one), atomically."""
        import flax.serialization

        policy = evaluation_policy(self.loop_state.policy_checkpoint, self.state)
        write_bytes_atomic(self.run_dir / name, flax.serialization.to_bytes(policy))
