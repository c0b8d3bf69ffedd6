"""Environments: the paper's tasks (``make_env``), PyBullet's Minitaur tasks (``bullet``), and
the fixed-horizon protocol as plain gymnasium wrappers (``wrappers``) for any RL code."""

from ilfo.envs.bullet import BULLET_ENVS
from ilfo.envs.make import (
    CONTACT_FORCE_DIMS,
    FULL_OBSERVATION_DIMS,
    HEALTHY_ANGLE_ENVS,
    SUPPORTED_ENVS,
    drop_contact_forces,
    make_env,
    match_observation_width,
    termination_is_finish,
)
from ilfo.envs.wrappers import (
    FixedHorizonScore,
    IgnoreTermination,
    TimeFeature,
    episode_scores,
    time_feature,
    with_time_feature,
)

__all__ = [
    "BULLET_ENVS",
    "CONTACT_FORCE_DIMS",
    "FULL_OBSERVATION_DIMS",
    "HEALTHY_ANGLE_ENVS",
    "SUPPORTED_ENVS",
    "FixedHorizonScore",
    "IgnoreTermination",
    "TimeFeature",
    "drop_contact_forces",
    "episode_scores",
    "make_env",
    "match_observation_width",
    "termination_is_finish",
    "time_feature",
    "with_time_feature",
]
