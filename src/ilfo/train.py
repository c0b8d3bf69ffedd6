"""The training loop: collect an episode, reward it, store it, update the agent, evaluate.

This is the one place where a rewarder and an agent meet (neither imports the other). It follows
the paper's code (docs/reproduction.md): uniformly random actions for ``start_steps``, then one
episode at a time with the policy frozen; at the end of each episode its OT rewards are computed
and the episode enters the replay buffer, then as many updates run as steps were collected
(``updates_per_step`` times as many; jitted calls). Every ``eval_every`` steps, deterministic
fixed-horizon episodes are scored.

A run directory holds ``config.json``, ``metrics.csv``, ``tb/`` (TensorBoard), ``checkpoints/``,
``policy.msgpack`` (the final policy), ``best_policy.msgpack`` and ``best_policy.json`` (the
best-evaluated policy, its step and score) and ``learning_curve.png``. Checkpoints are taken at
episode boundaries, where the whole state of the run is the agent state, the replay buffer, the
rewarder's generator and a few counters; every other source of randomness is derived from (seed,
episode index), so a resumed run reproduces the uninterrupted one exactly.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import numbers
import os
import shutil
import signal
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple

import flax.serialization
import jax
import numpy as np

from ilfo import demos as demo_io
from ilfo.agents import (
    SAC,
    TD3,
    SACConfig,
    TD3Config,
    ddpg_config,
    make_sac,
    make_td3,
    policy_of,
)
from ilfo.config import dataclass_from_dict
from ilfo.envs import episode_scores, make_env
from ilfo.paths import DATA_DIR
from ilfo.replay import ReplayBuffer
from ilfo.rewards import OOPS, PWIL, OOPSConfig, PWILConfig, Rewarder
from ilfo.rundir import (
    CHECKPOINTS_DIR,
    CONFIG_FILE,
    RunLock,
    checkpoint_steps,
    fault_point,
    latest_checkpoint,
    load_msgpack,
    load_npz,
    read_run_config,
    remove_incomplete_checkpoints,
    write_json_atomic,
)

Algo = Literal["oops-td3", "oops-ddpg", "oops-sac", "pwil-td3", "td3", "sac"]
ALGOS: tuple[str, ...] = ("oops-td3", "oops-ddpg", "oops-sac", "pwil-td3", "td3", "sac")
AGENT_OF: dict[str, Literal["td3", "sac"]] = {
    "oops-td3": "td3",
    "oops-ddpg": "td3",  # DDPG is a TD3 configuration (ddpg_config)
    "oops-sac": "sac",
    "pwil-td3": "td3",
    "td3": "td3",
    "sac": "sac",
}
"""The agent of each algo, by the name of its config field in ``TrainConfig``."""
SUB_CONFIGS: dict[str, type] = {
    "td3": TD3Config,
    "sac": SACConfig,
    "oops": OOPSConfig,
    "pwil": PWILConfig,
}
"""The agent and rewarder configs a ``TrainConfig`` holds, by field name."""
CHECKPOINT_SCHEMA = 1
BEST_POLICY_FILE = "best_policy.msgpack"
BEST_POLICY_INFO = "best_policy.json"  # the step and evaluation of best_policy.msgpack
POTENTIALS_FILE = "rewarder_potentials.npz"  # in a checkpoint: OOPS's warm-start potentials


@dataclass(frozen=True)
class TrainConfig:
    """One training run. Defaults: OOPS+TD3 on Hopper-v5 from one demo, as in the paper."""

    env: str = "Hopper-v5"
    """Gymnasium environment id."""
    algo: Algo = "oops-td3"
    """Rewarder + agent: oops-td3, oops-ddpg, oops-sac, pwil-td3, or td3 / sac on the true task
    reward (no demos)."""
    demos: str | None = None
    """Demonstration file (.npz); omit it (None) for the env's shipped expert demos
    (data/experts/<env>/demos.npz)."""
    num_demos: int = 1
    """How many of the file's demos to imitate (the first N)."""
    steps: int = 1_000_000
    """Environment steps in total (random ones included)."""
    start_steps: int = 10_000
    """Uniformly random steps before the policy acts."""
    updates_per_step: int = 1
    """Agent updates per environment step collected (the update-to-data ratio), run after each
    episode; 1 is the paper's. More spends compute to learn more from the same data."""
    preset: Literal["paper", "fast"] = "paper"
    """TD3/DDPG hyperparameters: paper (critics 1024-1024) or fast (critics 256-256); ``td3``
    (the --td3-* flags) changes single ones."""
    seed: int = 0
    """Seed of everything: environment, exploration, networks, demo draws."""
    fixed_horizon: bool | None = None
    """Run every episode to the full horizon, ignoring termination (the paper); None: on for
    imitation, off for true-reward algos."""
    horizon: int | None = None
    """Episode length; None: the environment's limit (1,000 for MuJoCo)."""
    healthy_angle_range: tuple[float, float] | None = None
    """Torso angle range (radians) outside which Hopper or Walker2d counts as fallen, in this
    run's training and evaluation episodes; None: the env's own ((-0.2, 0.2) for Hopper).
    Stricter ranges train experts with a margin from a fall; demos and the paper's scores always
    use the env's own range."""
    eval_every: int = 5_000
    """Evaluate every this many environment steps."""
    eval_episodes: int = 10
    """Deterministic episodes per evaluation."""
    best_by: Literal["score", "return"] = "score"
    """Which evaluation picks best_policy.msgpack: ``score`` (the paper's fixed-horizon score)
    or ``return`` (the standard return, which stops at the first fall: what an expert is judged
    by; ``ilfo expert train`` uses it)."""
    checkpoint_every: int = 50_000
    """Checkpoint every this many environment steps (and on Ctrl-C, and at the end)."""
    checkpoint_minutes: float = 10.0
    """Also checkpoint when this many minutes of wall-clock time have passed since the last
    checkpoint (or the start), so that a crash loses at most that much of any run, short runs
    included; 0 turns the clock off (steps only)."""
    replay_capacity: int = 1_000_000
    """Replay buffer size in transitions."""
    out: str = "runs"
    """Parent directory of the run directory."""
    td3: TD3Config | None = None
    """TD3/DDPG agent (algos oops-td3, oops-ddpg, pwil-td3, td3); None: the preset's
    (``TD3Config.paper()`` or ``.fast()``). Whatever is given, the trainer sets ``max_time`` to
    the episode horizon, keeps ``time_augmentation`` only where observations carry the time
    feature (fixed-horizon runs), and applies ``ddpg_config`` for oops-ddpg."""
    sac: SACConfig | None = None
    """SAC agent (algos oops-sac, sac); None: ``SACConfig()``, Haarnoja et al.'s defaults."""
    oops: OOPSConfig | None = None
    """OOPS rewarder (algos oops-*); None: the paper's defaults. Its ``seed`` is always replaced
    by this config's ``seed``, so that one seed sets a whole run (seed sweeps with a custom OOPS
    config stay seed sweeps)."""
    pwil: PWILConfig | None = None
    """PWIL rewarder (algo pwil-td3); None: the paper's defaults (``PWILConfig()``)."""

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(f"unknown algo {self.algo!r}; choose one of {', '.join(ALGOS)}")
        for name, cls in SUB_CONFIGS.items():  # dicts, as read back from config.json
            object.__setattr__(self, name, dataclass_from_dict(cls, getattr(self, name), name))
        used = (self.agent_kind, self.rewarder_kind)
        for name in SUB_CONFIGS:
            if getattr(self, name) is not None and name not in used:
                rewarder = f"the {self.rewarder_kind.upper()}" if self.rewarder_kind else "no"
                raise ValueError(
                    f"{name} settings (--{name}-* flags) do not apply to algo {self.algo!r}, "
                    f"which uses the {self.agent_kind.upper()} agent and {rewarder} rewarder; "
                    f"{name} is for {', '.join(algos_using(name))}"
                )
        if self.preset not in ("paper", "fast"):
            raise ValueError(f"preset must be 'paper' or 'fast', got {self.preset!r}")
        if self.best_by not in ("score", "return"):
            raise ValueError(f"best_by must be 'score' or 'return', got {self.best_by!r}")
        counts = (
            "steps",
            "eval_every",
            "eval_episodes",
            "checkpoint_every",
            "num_demos",
            "replay_capacity",
            "updates_per_step",
        )
        for name in (*counts, "start_steps", "seed", "horizon"):
            value = getattr(self, name)
            # 1e6 or True would pass the range checks and fail far from here, or not at all.
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            object.__setattr__(self, name, int(value))  # numpy integers: JSON needs int
        for name in counts:
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.start_steps < 0:
            raise ValueError(f"start_steps must be >= 0, got {self.start_steps}")
        minutes = self.checkpoint_minutes
        if isinstance(minutes, bool) or not isinstance(minutes, numbers.Real):
            raise ValueError(f"checkpoint_minutes must be a number, got {minutes!r}")
        if not (math.isfinite(minutes) and minutes >= 0):
            raise ValueError(f"checkpoint_minutes must be >= 0 (0: off), got {minutes!r}")
        object.__setattr__(self, "checkpoint_minutes", float(minutes))
        if self.healthy_angle_range is not None:  # a list, as read back from config.json
            angles = tuple(float(v) for v in self.healthy_angle_range)
            if len(angles) != 2 or not angles[0] < angles[1]:
                raise ValueError(
                    f"healthy_angle_range must be (low, high) with low < high, "
                    f"got {self.healthy_angle_range}"
                )
            object.__setattr__(self, "healthy_angle_range", angles)

    @property
    def imitation(self) -> bool:
        """Whether the algo learns from demos (True) or from the task reward (False)."""
        return self.algo.startswith(("oops-", "pwil-"))

    @property
    def uses_fixed_horizon(self) -> bool:
        """The resolved ``fixed_horizon``."""
        return self.imitation if self.fixed_horizon is None else self.fixed_horizon

    @property
    def agent_kind(self) -> Literal["td3", "sac"]:
        """The algo's agent config field: ``td3`` (TD3 and DDPG) or ``sac``."""
        return AGENT_OF[self.algo]

    @property
    def rewarder_kind(self) -> Literal["oops", "pwil"] | None:
        """The algo's rewarder config field (``oops``, ``pwil``); None for the task reward."""
        return _rewarder_of(self.algo)

    def resolved_td3(self) -> TD3Config:
        """``td3`` if given, else the preset's ``TD3Config`` (before the trainer's settings: see
        ``agent_config``)."""
        if self.td3 is not None:
            return self.td3
        return TD3Config.paper() if self.preset == "paper" else TD3Config.fast()

    def resolved_sac(self) -> SACConfig:
        """``sac`` if given, else ``SACConfig()``."""
        return SACConfig() if self.sac is None else self.sac

    def resolved_oops(self) -> OOPSConfig:
        """``oops`` if given, else the paper's ``OOPSConfig()``; its seed is always ``seed``."""
        return dataclasses.replace(self.oops or OOPSConfig(), seed=self.seed)

    def resolved_pwil(self) -> PWILConfig:
        """``pwil`` if given, else ``PWILConfig()``."""
        return PWILConfig() if self.pwil is None else self.pwil

    def agent_config(self, horizon: int) -> TD3Config | SACConfig:
        """The agent's config exactly as the run builds it, for episodes of ``horizon`` steps.

        TD3: time augmentation (a random time-to-go for each critic sample) needs the feature,
        which only fixed-horizon runs append to observations, so it is on where both the config
        and the run say so; ``max_time`` is the horizon; oops-ddpg applies ``ddpg_config``.
        """
        if self.agent_kind == "sac":
            return self.resolved_sac()
        td3 = self.resolved_td3()
        td3 = dataclasses.replace(
            td3,
            time_augmentation=td3.time_augmentation and self.uses_fixed_horizon,
            max_time=horizon,
        )
        return ddpg_config(td3) if self.algo.endswith("-ddpg") else td3

    def resolved(self, horizon: int) -> TrainConfig:
        """This config with the agent and rewarder configs of its algo filled in as the run uses
        them (``agent_config``, ``resolved_oops``, ``resolved_pwil``); the others None. What a
        run's config.json records, so that it shows every setting and builds the same run even
        if presets change."""
        agent = self.agent_config(horizon)
        return dataclasses.replace(
            self,
            td3=agent if isinstance(agent, TD3Config) else None,
            sac=agent if isinstance(agent, SACConfig) else None,
            oops=self.resolved_oops() if self.rewarder_kind == "oops" else None,
            pwil=self.resolved_pwil() if self.rewarder_kind == "pwil" else None,
        )


def algos_using(name: str) -> list[str]:
    """The algos whose agent or rewarder is configured by ``TrainConfig`` field ``name``."""
    return [a for a in ALGOS if name in (AGENT_OF[a], _rewarder_of(a))]


def _rewarder_of(algo: str) -> Literal["oops", "pwil"] | None:
    if algo.startswith("oops-"):
        return "oops"
    if algo.startswith("pwil-"):
        return "pwil"
    return None


class Agent(NamedTuple):
    """What the loop needs of an agent (TD3 and SAC both provide it)."""

    functions: TD3 | SAC
    time_feature: bool


def default_demos_path(env_id: str) -> Path:
    """The shipped expert demos of ``env_id``."""
    return DATA_DIR / "experts" / env_id / "demos.npz"


def load_demos(config: TrainConfig) -> list[demo_io.Episode]:
    """The first ``num_demos`` demos of the configured file, with clear errors."""
    path = Path(config.demos) if config.demos else default_demos_path(config.env)
    if not path.is_file():
        hint = "" if config.demos else " (no shipped expert demos for this env yet: pass --demos)"
        raise FileNotFoundError(f"no demonstration file at {path}{hint}")
    data = demo_io.load(path)
    if data.env_id and data.env_id != config.env:
        raise ValueError(f"{path} holds demos of {data.env_id}, not {config.env}")
    if config.num_demos > len(data.episodes):
        raise ValueError(f"--num-demos {config.num_demos}: {path} has {len(data.episodes)}")
    used_seeds = data.provenance.get("seeds", [])[: config.num_demos]
    fell = sorted(set(used_seeds) & set(data.provenance.get("kept_seeds_with_a_fall", [])))
    if fell:  # an expert shipped as the best reached (see its card); imitation copies the fall
        warnings.warn(
            f"{path}: the expert fell (the environment terminated) in the demos of seeds {fell}; "
            "these demos are the best this expert reached, not a full expert's",
            stacklevel=2,
        )
    return data.episodes[: config.num_demos]


def make_agent(
    config: TrainConfig, obs_dim: int, action_dim: int, max_action: float, horizon: int
) -> Agent:
    """Build the agent of ``config.algo`` (its config: ``config.agent_config(horizon)``).

    Fixed-horizon runs append the time feature remaining_steps / horizon to observations.
    """
    time_feature = config.uses_fixed_horizon
    agent_obs_dim = obs_dim + int(time_feature)
    agent_config = config.agent_config(horizon)
    if isinstance(agent_config, SACConfig):
        return Agent(make_sac(agent_config, agent_obs_dim, action_dim, max_action), time_feature)
    return Agent(make_td3(agent_config, agent_obs_dim, action_dim, max_action), time_feature)


def make_rewarder(config: TrainConfig, demos: list[np.ndarray]) -> Rewarder | None:
    """The rewarder of ``config.algo``; None for the true task reward."""
    if config.rewarder_kind == "oops":
        return OOPS(demos, config.resolved_oops())
    if config.rewarder_kind == "pwil":
        return PWIL(demos, config.resolved_pwil())
    return None


def network_normalizer(
    random_states: np.ndarray, expert_states: list[np.ndarray], std_floor: float = 0.33
) -> tuple[np.ndarray, np.ndarray]:
    """The agents' observation normaliser, as the paper's code fits it when the policy takes over.

    mean: of the random-exploration states. std: of the random states together with the expert
    states, the expert part repeated ``len(random) // len(expert)`` times (at least once) so that
    both weigh about the same (10,000 random states and one 1,000-step demo: the demo counts ten
    times); a zero std becomes 1, then std is floored at ``std_floor``. Without expert states
    (task-reward runs) the std is the random states' own.

    Args:
        random_states: (N, obs_dim) states of the random episodes (each episode's last left out).
        expert_states: demos' states, each (T_i, obs_dim) (each demo's last left out).
    """
    random_states = np.asarray(random_states, dtype=np.float64)
    pool = [random_states]
    if expert_states:
        expert = np.concatenate(expert_states).astype(np.float64)
        pool += [expert] * max(1, len(random_states) // len(expert))
    states = np.concatenate(pool)
    std = states.std(axis=0, ddof=1) if len(states) > 1 else np.ones(states.shape[1])
    std = np.where(np.isclose(std, 0.0), 1.0, std)
    return random_states.mean(axis=0), np.maximum(std, std_floor)


def run_name(config: TrainConfig) -> str:
    """env__algo__seed__time, CleanRL style."""
    return f"{config.env}__{config.algo}__{config.seed}__{time.strftime('%Y%m%d-%H%M%S')}"


def with_time(observations: np.ndarray, horizon: int) -> np.ndarray:
    """Append remaining_steps / horizon to each of an episode's observations (T + 1, d)."""
    remaining = (horizon - np.arange(len(observations))) / horizon
    return np.concatenate([observations, remaining[:, None]], axis=1)


METRIC_FIELDS = [
    "step",
    "episode",
    "wall_time",
    "steps_per_s",
    "proxy_return",
    "train_task_return",
    "critic_loss",
    "actor_loss",
    "eval_score",
    "eval_return",
    "eval_score_norm",
    "eval_return_norm",
    "eval_ot_distance",
]


class Trainer:
    """A training run in a run directory; ``Trainer.resume(run_dir)`` continues one."""

    def __init__(self, config: TrainConfig, run_dir: Path, *, progress: bool = True) -> None:
        self.config = config
        self.run_dir = Path(run_dir)
        self.progress = progress
        self.resume_command = f"ilfo train --resume {self.run_dir}"
        """What the interrupt message tells the user to run to continue (the CLI may change it)."""
        angles = config.healthy_angle_range
        self.env = make_env(
            config.env,
            config.uses_fixed_horizon,
            horizon=config.horizon,
            healthy_angle_range=angles,
        )
        self.horizon = int(self.env.spec.max_episode_steps)
        self.eval_env = make_env(config.env, True, horizon=self.horizon, healthy_angle_range=angles)
        obs_space, act_space = self.env.observation_space, self.env.action_space
        self.obs_dim = int(np.prod(obs_space.shape))
        self.action_dim = int(np.prod(act_space.shape))
        if not np.allclose(act_space.high, -act_space.low) or not np.allclose(
            act_space.high, act_space.high.flat[0]
        ):
            raise ValueError(f"{config.env}: actions must lie in a symmetric box [-a, a]")
        self.max_action = float(act_space.high.flat[0])

        if config.imitation:
            episodes = load_demos(config)
            self.demos = [e.observations for e in episodes]
            if self.demos[0].shape[1] != self.obs_dim:
                raise ValueError(
                    f"demos have observations of dimension {self.demos[0].shape[1]}, "
                    f"{config.env} has {self.obs_dim}"
                )
            returns = [e.task_score for e in episodes if e.task_score is not None]
            self.demo_return = float(np.mean(returns)) if returns else math.nan
            self.distance_probe: OOPS | None = OOPS(self.demos[:1])
        else:
            self.demos, self.demo_return, self.distance_probe = [], math.nan, None
        self.rewarder = make_rewarder(config, self.demos)
        self.agent = make_agent(
            config, self.obs_dim, self.action_dim, self.max_action, self.horizon
        )
        agent_obs_dim = self.obs_dim + int(self.agent.time_feature)
        self.state = self.agent.functions.init(config.seed)
        self.buffer = ReplayBuffer(config.replay_capacity, agent_obs_dim, self.action_dim)
        self.step = 0
        self.episode = 0
        self.random_states: list[np.ndarray] = []
        self.last_eval: dict[str, float] = {}
        self.elapsed = 0.0
        self._tb: Any = None  # TensorBoard writer, opened with the first metrics row
        self.best_eval: dict[str, float] = {}
        """The best evaluation so far by ``config.best_by``, with its step."""
        self._lock = RunLock(self.run_dir)  # held while this trainer writes the run directory
        self._resumed = False  # set by ``resume``: the run directory holds this run already
        self._tb_purge_step: int | None = None  # set by ``resume``: see ``_write_metrics``

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
            return self._train()
        finally:
            if self._tb is not None:
                self._tb.close()
                self._tb = None
            self._lock.release()

    def _train(self) -> Path:
        cfg = self.config
        config_path = self.run_dir / CONFIG_FILE
        if not self._resumed:
            if config_path.exists():
                raise ValueError(
                    f"{self.run_dir} holds a run already: continue it with "
                    "Trainer.resume (ilfo train --resume), or choose another directory"
                )
            resolved = cfg.resolved(self.horizon)  # every setting, as the run uses it
            write_json_atomic(config_path, dataclasses.asdict(resolved))
        bar = _progress_bar(cfg.steps, self.step, self.progress)
        start_wall = time.perf_counter() - self.elapsed
        next_checkpoint = (self.step // cfg.checkpoint_every + 1) * cfg.checkpoint_every
        last_checkpoint = self.step
        checkpoint_seconds = 60.0 * cfg.checkpoint_minutes or math.inf
        last_checkpoint_time = time.monotonic()
        try:
            with _stop_requests() as stop:
                while self.step < cfg.steps:
                    t0 = time.perf_counter()
                    row = self._episode()
                    self.elapsed = time.perf_counter() - start_wall
                    row["wall_time"] = round(self.elapsed, 3)
                    row["steps_per_s"] = round(row.pop("_steps") / (time.perf_counter() - t0), 1)
                    self._write_metrics(row)
                    fault_point("episode_end")
                    bar.update(self.step - bar.n)
                    bar.set_postfix(_postfix(row, self.last_eval), refresh=False)
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
            print(
                f"\ninterrupted: checkpoint at step {last_checkpoint}; continue with "
                f"`{self.resume_command}`"
            )
            raise
        bar.close()
        self._save_policy()
        plot_runs([self.run_dir], self.run_dir / "learning_curve.png")
        return self.run_dir

    def _episode(self) -> dict[str, Any]:
        """Collect, reward, store and learn from one episode; evaluate when due."""
        cfg = self.config
        funcs = self.agent.functions
        random_phase = self.step < cfg.start_steps
        if not random_phase and not bool(self.state.normalizer_set):
            self._fit_normalizer()
        rng = np.random.default_rng([cfg.seed, self.episode])
        env_seed = int(rng.integers(2**31))
        obs, _ = self.env.reset(seed=env_seed)
        observations, actions, task_rewards, env_terminated = [obs], [], [], []
        explore_key = jax.random.fold_in(jax.random.PRNGKey(cfg.seed), self.episode)
        # All of the episode's exploration keys at once, as numpy: one dispatch, not one a step.
        step_keys = np.asarray(jax.random.split(explore_key, self.horizon))
        policy = policy_of(self.state)  # frozen for the episode; few leaves: fast dispatch
        terminated = False
        for t in range(self.horizon):
            if random_phase:
                action = rng.uniform(-self.max_action, self.max_action, self.action_dim)
            else:
                agent_obs = self._agent_obs(obs, t)
                key = step_keys[t]
                action = np.asarray(funcs.act(policy, agent_obs, key), dtype=np.float64)
            obs, reward, terminated, truncated, info = self.env.step(action)
            observations.append(obs)
            actions.append(action)
            task_rewards.append(float(reward))
            env_terminated.append(bool(info.get("env_terminated", terminated)))
            if terminated or truncated:
                break
        observations = np.asarray(observations)
        num_steps = len(actions)
        self.step += num_steps
        self.episode += 1

        if self.rewarder is not None:
            rewards = self.rewarder(observations).rewards
        else:
            rewards = np.asarray(task_rewards)
            if cfg.uses_fixed_horizon:
                rewards = np.where(env_terminated, 0.0, rewards)
        agent_obs = (
            with_time(observations, self.horizon) if self.agent.time_feature else observations
        )
        # The paper's code cuts bootstrapping at the end of a fixed-horizon episode (its time
        # feature is then 0); standard mode bootstraps through truncation only.
        done = terminated or (cfg.uses_fixed_horizon and num_steps == self.horizon)
        self.buffer.add_episode(agent_obs, np.asarray(actions), rewards, terminated=done)
        if random_phase:
            self.random_states.append(observations[:-1])

        row: dict[str, Any] = {
            "step": self.step,
            "episode": self.episode,
            "proxy_return": round(float(np.sum(rewards)), 4),
            "train_task_return": round(float(np.sum(task_rewards)), 4),
            "_steps": num_steps,
        }
        if not random_phase:
            self.state, metrics = self._update(num_steps * cfg.updates_per_step)
            row["critic_loss"] = round(metrics["critic_loss"], 5)
            row["actor_loss"] = round(metrics["actor_loss"], 5)
        if self.step // cfg.eval_every > (self.step - num_steps) // cfg.eval_every:
            self.last_eval = self.evaluate()
            row.update(self.last_eval)
            best_key = f"eval_{cfg.best_by}"
            if self.last_eval[best_key] > self.best_eval.get(best_key, -math.inf):
                self.best_eval = {"step": self.step, **self.last_eval}
                self._save_policy(BEST_POLICY_FILE)
                info = {**self.best_eval, "elapsed": self.elapsed}
                write_json_atomic(self.run_dir / BEST_POLICY_INFO, info)
        return row

    def _update(self, num_updates: int) -> tuple[Any, dict[str, float]]:
        """``num_updates`` agent updates, run as jitted chunks of power-of-two sizes.

        ``update`` compiles once per number of updates; episodes of every length would each
        compile anew, whereas powers of two compile at most log2(horizon * updates_per_step) + 1
        times. Every update draws its keys from the state, so chunks give exactly the updates
        one call would.
        """
        state, totals = self.state, {"critic_loss": 0.0, "actor_loss": 0.0}
        remaining, chunk = num_updates, 1 << (num_updates.bit_length() - 1)
        while remaining:
            if chunk <= remaining:
                state, metrics = self.agent.functions.update(
                    state, self.buffer.data, self.buffer.size, num_updates=chunk
                )
                for name in totals:
                    totals[name] += float(metrics[name]) * chunk
                remaining -= chunk
            chunk >>= 1
        return state, {name: total / num_updates for name, total in totals.items()}

    def _agent_obs(self, obs: np.ndarray, t: int) -> np.ndarray:
        if self.agent.time_feature:
            return np.append(obs, (self.horizon - t) / self.horizon).astype(np.float32)
        return np.asarray(obs, dtype=np.float32)

    def _fit_normalizer(self) -> None:
        """Fix the networks' normaliser once, when the policy takes over: see
        ``network_normalizer``."""
        random_states = (
            np.concatenate(self.random_states)
            if self.random_states
            else np.zeros((1, self.obs_dim))
        )
        mean, std = network_normalizer(random_states, [d[:-1] for d in self.demos])
        if self.agent.time_feature:  # the time feature is already in [0, 1]
            mean, std = np.append(mean, 0.0), np.append(std, 1.0)
        self.state = self.agent.functions.set_normalizer(self.state, mean, std)
        self.random_states = []

    # ------------------------------------------------------------------------ evaluation
    def evaluate(self) -> dict[str, float]:
        """Deterministic fixed-horizon episodes: both scores, normalised, and OT distance."""
        seeds = [10_000_019 * (self.config.seed + 1) + k for k in range(self.config.eval_episodes)]
        scored = score_policy(
            self.eval_env, self.agent, self.state, self.horizon, seeds, self.distance_probe
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

    # ------------------------------------------------------------------ files and resume
    def _write_metrics(self, row: dict[str, Any]) -> None:
        """Append a row to metrics.csv and its scalars to the TensorBoard events file."""
        if self._tb is None:
            self._tb = TensorBoardLog(self.run_dir / "tb", purge_step=self._tb_purge_step)
        self._tb.add_scalars(
            {k: v for k, v in row.items() if k not in ("step", "episode")}, row["step"]
        )
        path = self.run_dir / "metrics.csv"
        new = not path.exists()
        with path.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=METRIC_FIELDS)
            if new:
                writer.writeheader()
            writer.writerow({k: row.get(k, "") for k in METRIC_FIELDS})

    def save_checkpoint(self) -> Path:
        """Write the run's whole state at this episode boundary.

        Written in ``checkpoints/.tmp_step_N`` and renamed to ``step_N`` once complete (the
        rename is atomic), then older checkpoints are removed: a kill at any moment leaves at
        least one complete checkpoint, the newest of which resume finds by scanning
        (``rundir.latest_checkpoint``). TensorBoard is flushed first, so that its events hold
        every row up to the checkpoint, as metrics.csv does."""
        if self._tb is not None:
            self._tb.flush()
        root = self.run_dir / CHECKPOINTS_DIR
        final = root / f"step_{self.step:09d}"
        if latest_checkpoint(self.run_dir) == final:
            return final  # this step is checkpointed already: the state has not changed since
        tmp = root / f".tmp_step_{self.step:09d}"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        (tmp / "agent.msgpack").write_bytes(flax.serialization.to_bytes(self.state))
        self.buffer.save(tmp / "replay.npz")
        if self.random_states:
            np.savez(tmp / "random_states.npz", *self.random_states)
        save_potentials = getattr(self.rewarder, "save_potentials", None)
        if save_potentials is not None and (potentials := save_potentials()):
            np.savez(tmp / POTENTIALS_FILE, **potentials)  # OOPS's warm starts
        meta = {
            "schema": CHECKPOINT_SCHEMA,
            "step": self.step,
            "episode": self.episode,
            "elapsed": self.elapsed,
            "last_eval": self.last_eval,
            "best_eval": self.best_eval,
            "rewarder_rng": _rng_state(self.rewarder),
        }
        (tmp / "state.json").write_text(json.dumps(meta))  # last: see rundir.CHECKPOINT_FILES
        fault_point("checkpoint_before_rename")
        os.replace(tmp, final)
        fault_point("checkpoint_before_cleanup")
        for _, old in checkpoint_steps(self.run_dir)[:-1]:
            shutil.rmtree(old, ignore_errors=True)
        return final

    @classmethod
    def resume(
        cls, run_dir: str | Path, *, progress: bool = True, steps: int | None = None
    ) -> Trainer:
        """Reload a run from its newest checkpoint to continue it; ``steps`` may change its
        budget, down to the steps already done.

        Changes files only once the checkpoint has loaded: rows of metrics.csv logged after the
        checkpoint are dropped (they will be logged again, as TensorBoard's are purged), what a
        killed checkpoint write left is removed, and a new ``steps`` is written to config.json.
        A run killed before its first checkpoint starts again from step 0 (with a warning).
        The returned trainer owns the run directory (``RunDirInUse`` if another process does)
        until its ``train`` returns.
        """
        run_dir = Path(run_dir)
        raw = read_run_config(run_dir)
        if steps is not None:
            raw = {**raw, "steps": steps}
        lock = RunLock(run_dir).acquire()
        try:
            config = config_from_dict(raw, run_dir / CONFIG_FILE)
            trainer = cls(config, run_dir, progress=progress)
            checkpoint = latest_checkpoint(run_dir)
            if checkpoint is None:
                warnings.warn(
                    f"{run_dir} has no complete checkpoint yet: the run starts again from step 0",
                    stacklevel=2,
                )
            else:
                trainer._load_checkpoint(checkpoint)
            if trainer.step > config.steps:
                raise ValueError(
                    f"{run_dir} has done {trainer.step} steps already (its checkpoint): --steps "
                    f"{config.steps} would shorten it; pass at least {trainer.step}"
                )
            remove_incomplete_checkpoints(run_dir)
            if steps is not None:
                write_json_atomic(run_dir / CONFIG_FILE, raw)
            _truncate_metrics(run_dir / "metrics.csv", trainer.step)
        except BaseException:
            lock.release()
            raise
        trainer._lock, trainer._resumed = lock, True
        trainer._tb_purge_step = trainer.step + 1
        return trainer

    @classmethod
    def from_checkpoint(
        cls, run_dir: str | Path, *, progress: bool = True, with_replay: bool = True
    ) -> Trainer:
        """A trainer in the state of the run's newest checkpoint; changes no file."""
        run_dir = Path(run_dir)
        config = config_from_dict(read_run_config(run_dir), run_dir / CONFIG_FILE)
        checkpoint = latest_checkpoint(run_dir)
        if checkpoint is None:
            raise FileNotFoundError(f"{run_dir} has no checkpoint to resume from")
        trainer = cls(config, run_dir, progress=progress)
        trainer._load_checkpoint(checkpoint, with_replay=with_replay)
        return trainer

    def _load_checkpoint(self, ckpt: Path, with_replay: bool = True) -> None:
        """Restore the state saved in checkpoint directory ``ckpt``; a damaged or mismatched
        file is a ValueError naming it."""
        state_path = ckpt / "state.json"
        try:
            meta = json.loads(state_path.read_text(encoding="utf-8"))
            if meta.get("schema") != CHECKPOINT_SCHEMA:
                raise ValueError(f"checkpoint schema {meta.get('schema')}, expected 1")
            step, episode = int(meta["step"]), int(meta["episode"])
            elapsed, last_eval = float(meta["elapsed"]), dict(meta["last_eval"])
            best_eval, rewarder_rng = dict(meta.get("best_eval", {})), meta["rewarder_rng"]
        except (ValueError, KeyError, TypeError, AttributeError) as err:
            raise ValueError(f"{state_path} is not a readable checkpoint state ({err})") from None
        self.state = load_msgpack(self.state, ckpt / "agent.msgpack", "agent checkpoint")
        if with_replay:
            buffer = ReplayBuffer.load(ckpt / "replay.npz")
            expected = (self.buffer.obs_dim, self.buffer.action_dim)
            if (buffer.obs_dim, buffer.action_dim) != expected:
                raise ValueError(
                    f"{ckpt / 'replay.npz'}: transitions of (obs, action) dims "
                    f"{(buffer.obs_dim, buffer.action_dim)}, this run's config makes {expected}"
                )
            self.buffer = buffer
        self.step, self.episode, self.elapsed = step, episode, elapsed
        self.last_eval, self.best_eval = last_eval, best_eval
        if rewarder_rng is not None and self.rewarder is not None:
            self.rewarder.rng.bit_generator.state = rewarder_rng  # type: ignore[attr-defined]
        potentials_path = ckpt / POTENTIALS_FILE
        if potentials_path.is_file() and self.rewarder is not None:
            potentials = load_npz(potentials_path, "Sinkhorn potentials")
            self.rewarder.load_potentials(potentials)  # type: ignore[attr-defined]
        random_path = ckpt / "random_states.npz"
        if random_path.is_file():
            arrays = load_npz(random_path, "random-phase states")
            self.random_states = [arrays[k] for k in sorted(arrays, key=_arr_index)]

    def _save_policy(self, name: str = "policy.msgpack") -> None:
        """The policy alone (actor parameters and observation normaliser), atomically."""
        tmp = self.run_dir / f".{name}.tmp"
        tmp.write_bytes(flax.serialization.to_bytes(policy_of(self.state)))
        os.replace(tmp, self.run_dir / name)


# ------------------------------------------------------------------------------ helpers
class Rollout(NamedTuple):
    """One evaluation episode: observations (T + 1, d), task rewards (T,), terminations (T,),
    and rendered frames (empty unless asked for)."""

    observations: np.ndarray
    rewards: np.ndarray
    env_terminated: np.ndarray
    frames: list[np.ndarray]


def rollout_policy(
    env: Any, agent: Agent, state: Any, horizon: int, seed: int, render: bool = False
) -> Rollout:
    """A deterministic fixed-horizon episode of the agent's policy (``state``: an agent state
    or a ``Policy``)."""
    policy = policy_of(state)
    obs, _ = env.reset(seed=seed)
    observations, rewards, terminated_flags = [obs], [], []
    frames = []
    for t in range(horizon):
        agent_obs = np.append(obs, (horizon - t) / horizon) if agent.time_feature else obs
        action = np.asarray(agent.functions.act(policy, agent_obs.astype(np.float32)))
        obs, reward, terminated, truncated, info = env.step(action.astype(np.float64))
        if render:
            frames.append(env.render())
        observations.append(obs)
        rewards.append(float(reward))
        terminated_flags.append(bool(info.get("env_terminated", terminated)))
        if terminated or truncated:
            break
    return Rollout(
        np.asarray(observations), np.asarray(rewards), np.asarray(terminated_flags), frames
    )


class PolicyScores(NamedTuple):
    """Scores of deterministic fixed-horizon episodes, one entry per episode."""

    scores: np.ndarray
    """The paper's fixed-horizon score (rewards of steps with a reported fall zeroed)."""
    returns: np.ndarray
    """The standard return (up to and including the first fall)."""
    distances: np.ndarray
    """OT distance of each episode to the probe's demo; empty without a probe."""
    frames: list[np.ndarray]
    """Rendered frames of the first episode, if asked for."""


def score_policy(
    env: Any,
    agent: Agent,
    state: Any,
    horizon: int,
    seeds: list[int],
    distance_probe: Any = None,
    render_first: bool = False,
) -> PolicyScores:
    """Roll out the deterministic policy once per seed and score each episode."""
    scores, returns, distances, frames = [], [], [], []
    for k, seed in enumerate(seeds):
        rollout = rollout_policy(
            env, agent, state, horizon, seed=seed, render=render_first and k == 0
        )
        frames.extend(rollout.frames)
        fixed, standard = episode_scores(rollout.rewards, rollout.env_terminated)
        scores.append(fixed)
        returns.append(standard)
        if distance_probe is not None:
            distances.append(distance_probe(rollout.observations).distance)
    return PolicyScores(np.array(scores), np.array(returns), np.array(distances), frames)


def config_from_dict(raw: dict[str, Any], source: str | Path) -> TrainConfig:
    """A ``TrainConfig`` from a dict read from a file (config.json, expert.json); a ValueError
    names ``source`` and the setting at fault (an unknown key, a value of the wrong type)."""
    known = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ValueError(
            f"{source}: unknown setting(s) {', '.join(map(repr, unknown))} (written by another "
            "ilfo version, or edited?)"
        )
    try:
        return TrainConfig(**raw)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{source}: {err}") from None


def _rng_state(rewarder: Any) -> dict | None:
    rng = getattr(rewarder, "rng", None)
    return None if rng is None else rng.bit_generator.state


def _arr_index(name: str) -> int:
    return int(name.split("_")[-1])


def _truncate_metrics(path: Path, step: int) -> None:
    """Drop rows logged after the checkpoint: the resumed run writes them again."""
    if not path.is_file():
        return
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=METRIC_FIELDS)
        writer.writeheader()
        writer.writerows(r for r in rows if int(r["step"]) <= step)


class TensorBoardLog:
    """Scalars to a TensorBoard events file in ``logdir``, written synchronously and flushed by
    ``flush``: tensorboardX's SummaryWriter queues events for a thread whose flush does not wait
    for the queue, so a kill could lose events logged before a checkpoint.

    ``purge_step`` S (a resumed run: its checkpoint's step + 1) starts the file with
    TensorBoard's session-start marker at S, which hides the events at S and after that an
    earlier process wrote, as metrics.csv drops those rows."""

    def __init__(self, logdir: Path, purge_step: int | None = None) -> None:
        from tensorboardX.event_file_writer import EventsWriter
        from tensorboardX.proto.event_pb2 import Event, SessionLog
        from tensorboardX.summary import scalar

        self._event, self._scalar = Event, scalar
        logdir.mkdir(parents=True, exist_ok=True)
        # One file per process and start: names hold the time in seconds only.
        suffix = f".{os.getpid()}.{purge_step or 0}"
        self._writer = EventsWriter(str(logdir / "events"), filename_suffix=suffix)
        if purge_step is not None:
            start = SessionLog(status=SessionLog.START)
            event = Event(wall_time=time.time(), step=purge_step, session_log=start)
            self._writer.write_event(event)

    def add_scalars(self, values: dict[str, Any], step: int) -> None:
        """Log every int or float of ``values`` at ``step``."""
        now = time.time()
        for tag, value in values.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                summary = self._scalar(tag, float(value))
                self._writer.write_event(self._event(wall_time=now, step=step, summary=summary))

    def flush(self) -> None:
        """Write what was logged to the file."""
        self._writer.flush()

    def close(self) -> None:
        """Flush and close the file."""
        self._writer.close()


class _StopRequest:
    """Set by the first Ctrl-C or SIGTERM; the loop stops at the next episode boundary."""

    requested = False


@contextmanager
def _stop_requests() -> Iterator[_StopRequest]:
    """The first SIGINT/SIGTERM asks the loop to checkpoint and stop after the current episode
    (a run is consistent only between episodes); the second raises KeyboardInterrupt at once."""
    stop = _StopRequest()

    def handler(signum: int, frame: Any) -> None:
        if stop.requested:
            raise KeyboardInterrupt
        stop.requested = True
        print("\nstopping after this episode (Ctrl-C again to quit at once)", flush=True)

    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.getsignal(sig)
            signal.signal(sig, handler)
    except ValueError:  # not the main thread: signals keep their default behaviour
        previous = {}
    try:
        yield stop
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _progress_bar(total: int, initial: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        disable=not enabled,
        unit="step",
        dynamic_ncols=True,
        smoothing=0.1,
    )


def _postfix(row: dict[str, Any], last_eval: dict[str, float]) -> dict[str, Any]:
    out: dict[str, Any] = {"sps": row.get("steps_per_s"), "proxy": row.get("proxy_return")}
    if "eval_score_norm" in last_eval:
        out["eval"] = last_eval["eval_score_norm"]
    elif "eval_score" in last_eval:
        out["eval"] = last_eval["eval_score"]
    return out


def read_metrics(run_dir: Path) -> list[dict[str, str]]:
    """The rows of a run's metrics.csv."""
    with (Path(run_dir) / "metrics.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def plot_runs(run_dirs: list[Path], out: Path, metric: str | None = None) -> Path:
    """Evaluation curves of runs, grouped by env and algo: mean over seeds with min-max band.

    ``metric`` defaults to the normalised score where demos gave a return, else the raw score.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    chosen = metric
    for run_dir in run_dirs:
        cfg = json.loads((Path(run_dir) / "config.json").read_text())
        rows = [r for r in read_metrics(run_dir) if r.get("eval_score")]
        if not rows:
            continue
        name = chosen or ("eval_score_norm" if rows[0].get("eval_score_norm") else "eval_score")
        chosen = name
        steps = np.array([float(r["step"]) for r in rows])
        values = np.array([float(r[name]) for r in rows])
        groups.setdefault(f"{cfg['env']} {cfg['algo']}", []).append((steps, values))
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, curves in groups.items():
        length = min(len(s) for s, _ in curves)
        steps = curves[0][0][:length]
        values = np.stack([v[:length] for _, v in curves])
        mean = values.mean(axis=0)
        ax.plot(steps, mean, label=f"{label} ({len(curves)} seed{'s' * (len(curves) > 1)})")
        if len(curves) > 1:
            ax.fill_between(steps, values.min(axis=0), values.max(axis=0), alpha=0.25)
    ax.set_xlabel("environment steps")
    ax.set_ylabel(chosen or "eval_score")
    ax.grid(alpha=0.3)
    if groups:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
