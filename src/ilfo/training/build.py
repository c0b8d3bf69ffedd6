"""Build a run's parts from its ``TrainConfig``: demos, agent, episode reward, normaliser.

Each builder reads the algorithm's parts from the registry (``ilfo.algos``); none knows the list
of algorithms.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np

from ilfo import demos as demo_io
from ilfo.agents import AgentFunctions
from ilfo.agents.base import OnPolicyAgentFunctions
from ilfo.algos import AGENT_PARTS, REWARD_PARTS, LearnedRewardPart, RewardPart
from ilfo.composition.learned import LearnedRewardSetup
from ilfo.envs import make_env, match_observation_width, with_time_feature
from ilfo.files import file_sha256
from ilfo.paths import default_demos_path
from ilfo.rewards import OOPS, EpisodeReward, expert_transitions
from ilfo.training.config import TrainConfig


class Agent(NamedTuple):
    """An agent's functions as a run uses them (which kind they are: ``Recipe.learner``), and
    whether its observations end with the time feature remaining_steps / horizon
    (fixed-horizon runs: ``agent_observations``)."""

    functions: AgentFunctions | OnPolicyAgentFunctions
    time_feature: bool


class EnvInfo(NamedTuple):
    """What the agent and the loop need to know of an environment."""

    horizon: int
    """Episode length (the time limit)."""
    obs_dim: int
    action_dim: int
    max_action: float
    """Actions lie in [-max_action, max_action] in every dimension."""


def make_run_env(
    config: TrainConfig,
    fixed_horizon: bool,
    horizon: int | None = None,
    render_mode: str | None = None,
) -> gym.Env:
    """An environment of the run's task as its config sets it (healthy angle range, contact
    forces), in fixed-horizon or standard mode; ``horizon`` None: the config's (or the env's
    own limit)."""
    return make_env(
        config.env,
        fixed_horizon,
        horizon=config.horizon if horizon is None else horizon,
        render_mode=render_mode,
        healthy_angle_range=config.healthy_angle_range,
        contact_forces=config.observes_contact_forces,
    )


def make_envs(config: TrainConfig) -> tuple[gym.Env, gym.Env, EnvInfo]:
    """The run's training environment (fixed-horizon or standard, as configured), its
    evaluation environment (always fixed-horizon, the paper's score) and their ``EnvInfo``."""
    env = make_run_env(config, config.uses_fixed_horizon)
    info = env_info(env, config.env)
    eval_env = make_run_env(config, True, horizon=info.horizon)
    return env, eval_env, info


def env_info(env: gym.Env, env_id: str) -> EnvInfo:
    """``EnvInfo`` of ``env``; a ValueError where observations are not a flat box of numbers
    or actions not a finite symmetric box [-a, a] (ilfo's agents act continuously)."""
    act_space, obs_space = env.action_space, env.observation_space
    for what, space in (("action", act_space), ("observation", obs_space)):
        if not isinstance(space, gym.spaces.Box):
            raise ValueError(
                f"{env_id} has a {type(space).__name__} {what} space ({space}): ilfo's agents "
                f"need a gymnasium Box of {what}s (continuous control, e.g. Hopper-v5)"
            )
    assert isinstance(act_space, gym.spaces.Box) and isinstance(obs_space, gym.spaces.Box)  # above
    high = np.asarray(act_space.high)
    symmetric = np.allclose(high, -np.asarray(act_space.low)) and np.allclose(high, high.flat[0])
    if not symmetric or not np.all(np.isfinite(high)):
        raise ValueError(f"{env_id}: actions must lie in a finite symmetric box [-a, a]")
    spec = env.spec  # gymnasium.make's, with the registered time limit
    assert spec is not None and spec.max_episode_steps is not None
    return EnvInfo(
        horizon=int(spec.max_episode_steps),
        obs_dim=int(np.prod(obs_space.shape)),
        action_dim=int(np.prod(act_space.shape)),
        max_action=float(high.flat[0]),
    )


@dataclass(frozen=True)
class DemoSource:
    """Which demonstrations a run imitates: what its ``demos.json`` records, so that a run
    stays tied to the file it imitated when that file is replaced (a re-exported expert)."""

    path: str
    """The demo file, absolute."""
    sha256: str
    """Of the file's bytes."""
    num_demos: int
    """Its first ``num_demos`` episodes are imitated."""
    mean_return: float
    """Their mean task score: what the run's normalised scores divide by (NaN: not recorded)."""

    def as_record(self, since_step: int) -> dict[str, object]:
        """The ``demos.json`` record; ``since_step``: the step from which the run is known to
        have imitated this file (0, or the step of a resume that found no record)."""
        mean = None if math.isnan(self.mean_return) else self.mean_return
        return {
            "path": self.path,
            "sha256": self.sha256,
            "num_demos": self.num_demos,
            "mean_return": mean,
            "since_step": since_step,
        }


class DemoSet(NamedTuple):
    """The demonstrations a run imitates."""

    observations: list[np.ndarray]
    """Each (T_i + 1, obs_dim); empty for task-reward algos."""
    mean_return: float
    """Their mean task score (what scores are divided by); NaN where none was recorded or it is
    not positive (scores are then left unnormalised)."""
    distance_probe: OOPS | None
    """OOPS against the first demo with the paper's defaults: the OT distance that evaluations
    log (None without demos)."""
    source: DemoSource | None
    """The file they come from (None without demos)."""


def load_demo_set(config: TrainConfig, obs_dim: int) -> DemoSet:
    """The run's demos (none for task-reward algos), checked against the env's ``obs_dim``."""
    if not config.imitation:
        return DemoSet([], math.nan, None, None)
    episodes = load_demos(config)
    observations = [e.observations for e in episodes]
    if not config.observes_contact_forces:  # demos of the full observation: the states without them
        observations = [match_observation_width(o, config.env, obs_dim) for o in observations]
    if observations[0].shape[1] != obs_dim:
        raise ValueError(
            f"demos have observations of dimension {observations[0].shape[1]}, "
            f"{config.env} has {obs_dim}"
        )
    returns = [e.task_score for e in episodes if e.task_score is not None]
    mean = float(np.mean(returns)) if returns else math.nan
    if not mean > 0:
        # A score over a zero or negative return means nothing (Pendulum: a learner at -1404
        # over a demo at -123 would read 11.4 of the expert), so scores stay unnormalised.
        if returns:
            warnings.warn(
                f"{demos_path(config)}: the demos' mean return is {mean:.6g}, not positive: "
                "normalised scores are undefined for this run, raw scores are logged",
                stacklevel=2,
            )
        mean = math.nan
    path = demos_path(config)
    source = DemoSource(str(path.resolve()), file_sha256(path), len(episodes), mean)
    return DemoSet(observations, mean, OOPS(observations[:1]), source)


def demos_path(config: TrainConfig) -> Path:
    """The demo file a run imitates: ``config.demos``, or the env's shipped expert demos."""
    return Path(config.demos) if config.demos else default_demos_path(config.env)


def load_demos(config: TrainConfig) -> list[demo_io.Episode]:
    """The first ``num_demos`` demos of the configured file, with clear errors."""
    path = demos_path(config)
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


def agent_observations(observations: np.ndarray, horizon: int, time_feature: bool) -> np.ndarray:
    """``rollout.agent_observation`` for a whole episode's observations (T + 1, d), as one
    array; the dtype of ``observations`` is kept (the replay buffer stores float32 itself)."""
    return with_time_feature(observations, horizon) if time_feature else observations


def make_agent(config: TrainConfig, env: EnvInfo, demos: Sequence[np.ndarray] | None) -> Agent:
    """Build the agent of ``config.algo`` (its config: ``config.agent_config(env.horizon)``).

    Fixed-horizon runs append the time feature remaining_steps / horizon to observations.
    Algos with a learned reward get the agent trained on it (``ilfo.composition.learned``), which
    learns from ``demos`` (each (T_i + 1, obs_dim)); ``demos=None`` builds it only as a template
    to read a saved state into (its reward's input statistics are then placeholders, zeros).
    """
    time_feature = config.uses_fixed_horizon
    algo = config.recipe
    part = AGENT_PARTS[algo.agent]
    dims = (env.obs_dim + int(time_feature), env.action_dim, env.max_action)
    agent_config = config.agent_config(env.horizon)
    if not algo.learned:
        assert part.make is not None  # None only for agents that need a learned reward
        return Agent(part.make(agent_config, *dims), time_feature)
    assert algo.reward is not None  # a learned reward's recipe names it
    reward_part = REWARD_PARTS[algo.reward]
    assert isinstance(reward_part, LearnedRewardPart) and part.make_learning is not None
    reward_config = config.part_config(algo.reward)
    reward = reward_part.make(reward_config)
    schedule = reward_part.schedule(reward_config)
    rollouts = None if reward_part.rollouts is None else reward_part.rollouts(reward_config)
    if demos is None:  # a template: the shapes matter, not the values
        demos = [np.zeros((env.horizon + 1, env.obs_dim), np.float32)] * max(
            1, -(-reward.batch_size // env.horizon)
        )
    # What the learner can visit: a demo's first `horizon` transitions (with --horizon below
    # the demos' length, its later ones would train the discriminator on states out of reach
    # and give the time feature negative values).
    demos = [d[: env.horizon + 1] for d in demos]
    setup = LearnedRewardSetup(
        reward=reward,
        schedule=schedule,
        # Batches are drawn with replacement; a batch larger than the demos would hide that
        # they are too few for the algo's settings.
        expert=expert_transitions(demos, min_count=reward.batch_size if schedule else 1),
        expert_agent_obs=jnp.asarray(
            np.concatenate([agent_observations(d, env.horizon, time_feature)[:-1] for d in demos])
        ),
        time_feature=time_feature,
        rollouts=rollouts,
        expert_trajectories=None if rollouts is None else expert_trajectories(demos, env.horizon),
    )
    functions = part.make_learning(agent_config, *dims, setup)
    return Agent(functions, time_feature)


def expert_trajectories(demos: Sequence[np.ndarray], horizon: int) -> jax.Array:
    """(E, horizon, obs_dim): each demo's states s_1..s_horizon, what the expert visits in an
    episode of ``horizon`` steps (the states a policy's rollouts are compared with); a
    ValueError where a demo is shorter."""
    short = [i for i, d in enumerate(demos) if len(d) < horizon + 1]
    if short:
        raise ValueError(
            f"demos {short} have fewer than the episode horizon's {horizon} steps: a reward "
            "learned from whole episodes compares them with the policy's (pass --horizon)"
        )
    return jnp.asarray(np.stack([np.asarray(d[1 : horizon + 1], np.float32) for d in demos]))


def make_reward(config: TrainConfig, demos: list[np.ndarray]) -> EpisodeReward | None:
    """The episode reward of ``config.algo``; None for the task reward and for learned rewards
    (the agent holds those: ``make_agent``)."""
    algo = config.recipe
    if algo.reward is None or algo.learned:
        return None
    part = REWARD_PARTS[algo.reward]
    assert isinstance(part, RewardPart)
    return part.make(demos, config.part_config(algo.reward))


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
