"""The algorithm registry: what ``--algo`` names, and the parts each algorithm is built from.

An algorithm is a ``Recipe``: an agent part (``td3``, ``sac``) and a reward part (``oops``,
``pwil``, or none for the task reward), with an optional change to the agent's config (DDPG is
a TD3 config). Parts are registered once in ``AGENT_PARTS`` and ``REWARD_PARTS``: the config
type, the factory, the defaults, and what the trainer sets itself. Everything that depends on
the list of algorithms reads it from here: ``TrainConfig``'s validation, the CLI's ``--algo``
choices and its flag groups, and the builders in ``ilfo.training.build``.

Adding an algorithm that combines existing parts is one ``Recipe`` in ``RECIPES``; a new part
is its module, one entry in ``AGENT_PARTS`` or ``REWARD_PARTS`` and one typed field of
``TrainConfig`` (named as the part) for its config (docs/architecture.md has a worked example).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilfo.agents import SACConfig, TD3Config, ddpg_config, make_sac, make_td3
from ilfo.rewards import OOPS, PWIL, EpisodeReward, OOPSConfig, PWILConfig


@dataclass(frozen=True, kw_only=True)
class Part:
    """What every part has: its config type and its flag group in ``ilfo train --help``."""

    config: type
    """Its frozen config dataclass; a ``seed`` field, where it has one, is the run's seed."""
    title: str
    """Its flag group's title."""
    description: str
    """Its flag group's description."""
    set_by_trainer: tuple[str, ...] = ()
    """Config fields the trainer sets (no flag)."""


@dataclass(frozen=True, kw_only=True)
class AgentPart(Part):
    """An RL agent the loop can train (TD3, SAC)."""

    make: Callable[..., Any]
    """``make(config, obs_dim, action_dim, max_action)`` -> the agent's functions
    (``ilfo.agents.AgentFunctions``)."""
    default: Callable[[str], Any]
    """``default(preset)`` -> the config used when none is given (``TrainConfig.preset``)."""
    for_run: Callable[[Any, int, bool], Any]
    """``for_run(config, horizon, fixed_horizon)`` -> the config as a run uses it (what the
    trainer sets: see ``set_by_trainer``)."""


@dataclass(frozen=True, kw_only=True)
class RewardPart(Part):
    """An imitation reward computed on each whole learner episode (``EpisodeReward``)."""

    make: Callable[[Sequence[np.ndarray], Any], EpisodeReward]
    """``make(demos, config)`` -> the reward; demos are observation arrays (T_i + 1, obs_dim)."""


@dataclass(frozen=True)
class Recipe:
    """One ``--algo``: an agent part and a reward part (None: the task reward)."""

    name: str
    """The ``--algo`` name."""
    agent: str
    """Key of ``AGENT_PARTS``."""
    reward: str | None
    """Key of ``REWARD_PARTS``; None learns from the environment's task reward."""
    summary: str
    """One line for ``--help`` and the docs."""
    adapt_agent: Callable[[Any], Any] | None = None
    """A change applied to the agent's config after the run's (e.g. ``ddpg_config``)."""

    @property
    def imitation(self) -> bool:
        """Whether it learns from demonstrations (a reward part) rather than the task reward."""
        return self.reward is not None


def _td3_default(preset: str) -> TD3Config:
    return TD3Config.paper() if preset == "paper" else TD3Config.fast()


def _td3_for_run(config: TD3Config, horizon: int, fixed_horizon: bool) -> TD3Config:
    # Time augmentation draws a time-to-go for each critic sample: it needs the time feature,
    # which only fixed-horizon runs append to observations.
    return dataclasses.replace(
        config, time_augmentation=config.time_augmentation and fixed_horizon, max_time=horizon
    )


AGENT_PARTS: dict[str, AgentPart] = {
    "td3": AgentPart(
        config=TD3Config,
        make=make_td3,
        default=_td3_default,
        for_run=_td3_for_run,
        title="TD3/DDPG agent",
        description=(
            "Defaults: the --preset's (paper | fast, shown as 'paper X, fast Y' where they "
            "differ); a flag here changes that one setting of the preset. oops-ddpg then applies "
            "DDPG's changes (one critic, no target smoothing, policy delay 1). Set by the "
            "trainer: max_time (the episode horizon); time augmentation applies only where "
            "observations carry the time feature (fixed-horizon runs)."
        ),
        set_by_trainer=("max_time",),
    ),
    "sac": AgentPart(
        config=SACConfig,
        make=make_sac,
        default=lambda preset: SACConfig(),
        for_run=lambda config, horizon, fixed_horizon: config,
        title="SAC agent",
        description="Defaults: Haarnoja et al. 2018.",
    ),
}
"""The agents, by the name of their ``TrainConfig`` field."""

REWARD_PARTS: dict[str, RewardPart] = {
    "oops": RewardPart(
        config=OOPSConfig,
        make=OOPS,
        title="OOPS rewarder",
        description="Defaults: the paper's. Set by the trainer: seed (the demo draws follow "
        "--seed).",
        set_by_trainer=("seed",),
    ),
    "pwil": RewardPart(
        config=PWILConfig,
        make=PWIL,
        title="PWIL rewarder",
        description="Defaults: the paper's.",
    ),
}
"""The episode rewards, by the name of their ``TrainConfig`` field."""

RECIPES: tuple[Recipe, ...] = (
    Recipe("oops-td3", "td3", "oops", "OOPS reward + TD3 with the PAL critic loss (the paper)"),
    Recipe("oops-ddpg", "td3", "oops", "OOPS reward + DDPG", adapt_agent=ddpg_config),
    Recipe("oops-sac", "sac", "oops", "OOPS reward + SAC"),
    Recipe("pwil-td3", "td3", "pwil", "PWIL-(s) reward + TD3 (the paper's PWIL baseline)"),
    Recipe("td3", "td3", None, "TD3 on the task reward (no demos)"),
    Recipe("sac", "sac", None, "SAC on the task reward (no demos; ilfo's experts)"),
)

ALGOS: dict[str, Recipe] = {recipe.name: recipe for recipe in RECIPES}
"""Every ``--algo``, by name."""

PART_CONFIGS: dict[str, type] = {
    **{name: part.config for name, part in AGENT_PARTS.items()},
    **{name: part.config for name, part in REWARD_PARTS.items()},
}
"""The config type of every part, by the name of its ``TrainConfig`` field."""


def recipe(name: str) -> Recipe:
    """The recipe of ``--algo name``, or a ValueError listing the choices."""
    try:
        return ALGOS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown algo {name!r}; choose one of {', '.join(ALGOS)}") from None


def algos_using(part: str) -> list[str]:
    """The algos built with part ``part`` (a key of ``AGENT_PARTS`` or ``REWARD_PARTS``)."""
    return [r.name for r in RECIPES if part in (r.agent, r.reward)]
