"""Imitation rewards. Episode rewards (OOPS, PWIL) map one learner episode's observations
(T + 1, obs_dim) to rewards (T,); learned rewards (the discriminator) are pure-JAX functions of
(s, s') with their own state, updated and queried inside the agent's update."""

from ilfo.rewards.base import (
    EpisodeReward,
    RewardOutput,
    RewardState,
    Standardizer,
    make_atoms,
)
from ilfo.rewards.discriminator import Discriminator, DiscriminatorConfig, DiscriminatorState
from ilfo.rewards.firl import FIRL, FIRLConfig, FIRLState, fkl_surrogate
from ilfo.rewards.learned import (
    LearnedReward,
    RolloutLearnedReward,
    Transitions,
    expert_transitions,
    sample_transitions,
)
from ilfo.rewards.oops import OOPS, OOPSConfig
from ilfo.rewards.pwil import PWIL, PWILConfig

__all__ = [
    "FIRL",
    "OOPS",
    "PWIL",
    "Discriminator",
    "DiscriminatorConfig",
    "DiscriminatorState",
    "EpisodeReward",
    "FIRLConfig",
    "FIRLState",
    "LearnedReward",
    "OOPSConfig",
    "PWILConfig",
    "RewardOutput",
    "RewardState",
    "RolloutLearnedReward",
    "Standardizer",
    "Transitions",
    "expert_transitions",
    "fkl_surrogate",
    "make_atoms",
    "sample_transitions",
]
