"""``make_env`` for the paper's gymnasium tasks, in fixed-horizon or standard mode.

Fixed-horizon mode (the paper's code) runs every episode to its full length: a termination the
environment reports is recorded in ``info["env_terminated"]`` and the episode goes on; only the
time limit ends it. Standard mode is plain gymnasium: an episode ends at termination (no
bootstrapping) or truncation (bootstrapping continues).

PyBullet's Minitaur and MinitaurDuck (``ilfo.envs.bullet``, registered here) need the optional
extra: ``pip install -e ".[bullet]"``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from ilfo.envs.bullet import BULLET_ENVS, register_bullet_envs
from ilfo.envs.wrappers import IgnoreTermination

register_bullet_envs()  # the Minitaur ids; pybullet itself is imported only by their make

SUPPORTED_ENVS: tuple[str, ...] = (
    "Hopper-v5",
    "Walker2d-v5",
    "HalfCheetah-v5",
    "Ant-v5",
    "Humanoid-v5",
    "BipedalWalker-v3",
    *BULLET_ENVS,  # pip install -e ".[bullet]"
    "Pendulum-v1",  # not in the paper: a seconds-long sanity task for tests
)


HEALTHY_ANGLE_ENVS: tuple[str, ...] = ("Hopper-v5", "Walker2d-v5")
"""Envs whose torso must stay in a healthy angle range (``make_env``'s ``healthy_angle_range``)."""

CONTACT_FORCE_DIMS: dict[str, int] = {"Ant-v5": 78, "Humanoid-v5": 78}
"""Envs whose observations end with the bodies' external contact forces (``cfrc_ext``, 13 bodies
x 6), and how many columns those are. The paper's v2 versions of these tasks carried them as
zeros (mujoco-py >= 2.0 left them unfilled); ``make_env(..., contact_forces=False)`` drops them."""
FULL_OBSERVATION_DIMS: dict[str, int] = {"Ant-v5": 105, "Humanoid-v5": 348}
"""The full observation width of the envs in ``CONTACT_FORCE_DIMS`` (gymnasium's defaults,
the contact forces included)."""


def env_spec(env_id: str) -> gym.envs.registration.EnvSpec:
    """gymnasium's registration of ``env_id``, or a ValueError listing the supported ids."""
    try:
        return gym.spec(env_id)
    except gym.error.Error:
        raise ValueError(f"unknown environment {env_id!r}; supported: {SUPPORTED_ENVS}") from None


def make_env(
    env_id: str,
    fixed_horizon: bool = True,
    seed: int | None = None,
    horizon: int | None = None,
    render_mode: str | None = None,
    healthy_angle_range: tuple[float, float] | None = None,
    contact_forces: bool = True,
) -> gym.Env:
    """Make a gymnasium environment.

    Args:
        env_id: One of ``SUPPORTED_ENVS`` (other registered ids work without guarantees).
        fixed_horizon: Run every episode to ``horizon`` steps, ignoring termination (the paper).
        seed: Seeds the first reset and the action space; later resets continue the same stream.
        horizon: Episode length; the environment's registered limit if None (1,000 for MuJoCo
            and Minitaur).
        render_mode: Passed to gymnasium (e.g. ``rgb_array`` for videos).
        healthy_angle_range: (low, high) torso angle in radians outside which Hopper or
            Walker2d is unhealthy (a fall: termination, no healthy reward); None: the env's
            own, (-0.2, 0.2) for Hopper-v5, (-1, 1) for Walker2d-v5. A stricter range trains
            experts that keep a margin from a fall (docs/experts.md).
        contact_forces: False drops the contact forces that end Ant-v5's and Humanoid-v5's
            observations (``CONTACT_FORCE_DIMS``; gymnasium's
            ``include_cfrc_ext_in_observation=False``): the information the paper's v2 tasks
            gave, whose contact forces were all zero.

    Returns:
        The environment, with ``env.spec.max_episode_steps`` equal to the horizon.

    Raises:
        ValueError: Unknown ``env_id``, a gymnasium optional dependency is missing, or a
            ``healthy_angle_range`` that is not (low < high) or for an env without one, or
            ``contact_forces=False`` for an env without contact forces in its observations.
        ImportError: A Minitaur id without PyBullet (``pip install -e ".[bullet]"``).
    """
    spec = env_spec(env_id)
    limit = (spec.max_episode_steps or 1000) if horizon is None else horizon
    if limit < 1:
        raise ValueError(f"horizon must be >= 1, got {horizon}")
    kwargs: dict[str, Any] = {}
    if healthy_angle_range is not None:
        if env_id not in HEALTHY_ANGLE_ENVS:
            raise ValueError(
                f"healthy_angle_range applies to {', '.join(HEALTHY_ANGLE_ENVS)}, not {env_id}"
            )
        low, high = (float(v) for v in healthy_angle_range)
        if not low < high:
            raise ValueError(f"healthy_angle_range needs low < high, got {healthy_angle_range}")
        kwargs["healthy_angle_range"] = (low, high)
    if not contact_forces:
        if env_id not in CONTACT_FORCE_DIMS:
            raise ValueError(
                f"contact_forces=False applies to {', '.join(CONTACT_FORCE_DIMS)}, not {env_id}"
            )
        kwargs["include_cfrc_ext_in_observation"] = False
    try:
        # Fixed horizon: no TimeLimit from gym.make (-1), whose render wrappers ("human",
        # "rgb_array_list") would sit outside it; the horizon's own goes outside them below.
        steps = -1 if fixed_horizon else limit
        env = gym.make(env_id, max_episode_steps=steps, render_mode=render_mode, **kwargs)
    except gym.error.DependencyNotInstalled as err:
        raise ValueError(f"{env_id} needs an optional dependency: {err}") from err
    if fixed_horizon:
        # Inside TimeLimit, so that the time limit still truncates at `limit`.
        env = gym.wrappers.TimeLimit(IgnoreTermination(env), max_episode_steps=limit)
    if seed is not None:
        env.reset(seed=seed)
        env.action_space.seed(seed)
    return env


# Envs whose termination also marks success: BipedalWalker terminates when the walker falls or
# walks off the start (reward exactly -100 on that step), and when it passes the end of the
# course (a normal shaping reward). In fixed-horizon episodes the walker walks on past the
# finish, every later step reported as terminated, so the fixed-horizon score counts them 0.
_FALL_REWARD = {"BipedalWalker-v3": -100.0}


def drop_contact_forces(observations: np.ndarray, env_id: str) -> np.ndarray:
    """Observations (..., d) of ``env_id`` with all its columns, without the contact forces at
    their end: what ``make_env(env_id, contact_forces=False)`` observes.

    Raises:
        ValueError: ``env_id`` has no contact forces in its observations, or ``observations``
            are not its full observation (``FULL_OBSERVATION_DIMS``).
    """
    if env_id not in CONTACT_FORCE_DIMS:
        raise ValueError(f"{env_id} has no contact forces in its observations")
    observations = np.asarray(observations)
    full = FULL_OBSERVATION_DIMS[env_id]
    kept = full - CONTACT_FORCE_DIMS[env_id]
    if observations.shape[-1] != full:  # else other columns would be cut in their place
        raise ValueError(
            f"observations of dimension {observations.shape[-1]} are not {env_id}'s full "
            f"observation ({full} columns, {kept} without its contact forces)"
        )
    return observations[..., :kept]


def match_observation_width(observations: np.ndarray, env_id: str, obs_dim: int) -> np.ndarray:
    """``observations`` (..., d) fitted to an env observing ``obs_dim`` columns: without their
    contact forces where they hold exactly ``obs_dim`` plus ``env_id``'s contact-force columns
    (demos of the full observation, for a run with ``contact_forces=False``); as they are
    otherwise (a mismatch is left for the caller to report)."""
    extra = CONTACT_FORCE_DIMS.get(env_id)
    if extra is not None and np.shape(observations)[-1] == obs_dim + extra:
        return drop_contact_forces(observations, env_id)
    return observations


def termination_is_finish(env_id: str, reward: float) -> bool:
    """Whether a step on which ``env_id`` reported termination, with task ``reward``, is the
    task completed (BipedalWalker reaching the end of its course) rather than a fall.

    Every termination of the MuJoCo and Minitaur tasks is a fall (unhealthy state)."""
    fall_reward = _FALL_REWARD.get(env_id)
    return fall_reward is not None and float(reward) != fall_reward
