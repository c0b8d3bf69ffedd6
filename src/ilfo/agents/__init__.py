"""Off-policy agents in JAX: TD3 (with PAL, time augmentation, DDPG as a config) and SAC.

Each agent is a frozen config dataclass, a state pytree and pure jitted functions built by a
factory (``make_td3``, ``make_sac``) that closes over the config. Agents know nothing of rewards:
they read transitions from a ``ilfo.replay.ReplayData``.
"""

from ilfo.agents._common import Policy, policy_of
from ilfo.agents.base import AgentFunctions
from ilfo.agents.critic_targets import augment_time, critic_loss, pal_loss
from ilfo.agents.sac import SAC, SACConfig, SACState, make_sac
from ilfo.agents.td3 import TD3, TD3Config, TD3State, ddpg_config, make_td3
from ilfo.networks import (
    MLP,
    Critic,
    CriticEnsemble,
    DeterministicActor,
    SquashedGaussianActor,
)

__all__ = [
    "MLP",
    "SAC",
    "TD3",
    "AgentFunctions",
    "Critic",
    "CriticEnsemble",
    "DeterministicActor",
    "Policy",
    "SACConfig",
    "SACState",
    "SquashedGaussianActor",
    "TD3Config",
    "TD3State",
    "augment_time",
    "critic_loss",
    "ddpg_config",
    "make_sac",
    "make_td3",
    "pal_loss",
    "policy_of",
]
