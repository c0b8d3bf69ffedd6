"""Episode rewards: from one learner episode's observations (T + 1, obs_dim) to rewards (T,)."""

from ilfo.rewards.base import (
    EpisodeReward,
    RewardOutput,
    RewardState,
    Standardizer,
    make_atoms,
)
from ilfo.rewards.oops import OOPS, OOPSConfig
from ilfo.rewards.pwil import PWIL, PWILConfig

__all__ = [
    "OOPS",
    "PWIL",
    "EpisodeReward",
    "OOPSConfig",
    "PWILConfig",
    "RewardOutput",
    "RewardState",
    "Standardizer",
    "make_atoms",
]
