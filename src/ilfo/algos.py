"""The algorithm registry: what ``--algo`` names, and the parts each algorithm is built from.

An algorithm is a ``Recipe``: an agent part (``td3``, ``sac``) and a reward part (an episode
reward: ``oops``, ``pwil``; a learned reward: ``discriminator``; or none for the task reward),
with an optional change to the agent's config (DDPG is a TD3 config) and an optional default
agent config of its own (the baselines' authors' settings). Parts are registered once in
``AGENT_PARTS`` and ``REWARD_PARTS``: the config
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
from typing import Any, Literal

import numpy as np

from ilfo.agents import SACConfig, TD3Config, ddpg_config, make_sac, make_td3
from ilfo.agents.policy_checkpoints import CheckpointSchedule
from ilfo.agents.td7 import TD7Config, make_td7
from ilfo.agents.trpo import TRPOConfig, make_trpo
from ilfo.composition.opolo import OPOLOConfig, make_opolo
from ilfo.rewards import (
    FIRL,
    OOPS,
    PWIL,
    Discriminator,
    DiscriminatorConfig,
    EpisodeReward,
    FIRLConfig,
    LearnedReward,
    OOPSConfig,
    PWILConfig,
    RolloutLearnedReward,
)
from ilfo.rewards.oops_adv import AdversarialOOPS, AdversarialOOPSConfig
from ilfo.rewards.sil import SIL, SILConfig


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

    make: Callable[..., Any] | None
    """``make(config, obs_dim, action_dim, max_action)`` -> the agent's functions
    (``ilfo.agents.AgentFunctions``); None for an agent that needs a learned reward."""
    default: Callable[[str], Any]
    """``default(preset)`` -> the config used when none is given (``TrainConfig.preset``)."""
    for_run: Callable[[Any, int, bool], Any]
    """``for_run(config, horizon, fixed_horizon)`` -> the config as a run uses it (what the
    trainer sets: see ``set_by_trainer``)."""
    make_learning: Callable[..., Any] | None = None
    """``make_learning(config, obs_dim, action_dim, max_action, setup)`` -> the agent's functions
    trained on a learned reward (``setup``: ``ilfo.composition.learned.LearnedRewardSetup``);
    None: the agent cannot use one."""
    on_policy: bool = False
    """Whether it learns from batches of its own fresh episodes (TRPO), not from a replay
    buffer: ``TrainConfig.updates_per_step`` does not apply to it."""
    policy_checkpoints: Callable[[Any], CheckpointSchedule | None] | None = None
    """``policy_checkpoints(config)`` -> the schedule of the policy checkpoints it is evaluated
    with (TD7's: ``ilfo.agents.policy_checkpoints``), None where its config turns them off;
    None: it has none."""


@dataclass(frozen=True, kw_only=True)
class RewardPart(Part):
    """An imitation reward computed on each whole learner episode (``EpisodeReward``)."""

    make: Callable[[Sequence[np.ndarray], Any], EpisodeReward]
    """``make(demos, config)`` -> the reward; demos are observation arrays (T_i + 1, obs_dim)."""
    learns_per_batch: bool = False
    """Whether it is a ``BatchLearningReward`` (SIL's critic): the loop calls its ``end_batch``
    each time the on-policy agent has learned from a batch."""


@dataclass(frozen=True, kw_only=True)
class LearnedRewardPart(Part):
    """A reward learned during training (``LearnedReward``), queried inside the agent's update."""

    make: Callable[[Any], LearnedReward | RolloutLearnedReward]
    """``make(config)`` -> the reward."""
    schedule: Callable[[Any], Any]
    """``schedule(config)`` -> its ``RewardSchedule`` (when it takes gradient steps on replay
    and expert batches), or None."""
    rollouts: Callable[[Any], Any] | None = None
    """``rollouts(config)`` -> its ``RolloutPlan`` where it learns from fresh episodes of the
    policy (f-IRL); None otherwise."""


LearnerKind = Literal["off_policy", "learned_reward", "on_policy"]


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
    fixed_horizon: bool | None = None
    """The episodes it trains on when a run does not say (``TrainConfig.fixed_horizon``): None,
    ilfo's protocol (fixed-horizon for imitation, standard for the task reward); False:
    standard episodes, ending at a fall, where the algo's own code needs them (SIL, f-IRL,
    PWIL-(s))."""
    start_steps: int | None = None
    """Uniformly random steps before the policy acts when a run does not say
    (``TrainConfig.start_steps``): None, ilfo's protocol (10,000, the OOPS paper's); a number
    where the algo's own code differs and needs it (f-IRL)."""
    part_defaults: Callable[[str], dict[str, Any]] | None = None
    """``part_defaults(env_id)`` -> {part name: config}: the recipe's own defaults for its
    parts, where a run gives none (a baseline's authors' settings, which may differ by env),
    in place of the parts' own (the agent's ``--preset``); flags change single settings."""

    @property
    def imitation(self) -> bool:
        """Whether it learns from demonstrations (a reward part) rather than the task reward."""
        return self.reward is not None

    @property
    def learned(self) -> bool:
        """Whether its reward is learned during training (a ``LearnedRewardPart``)."""
        return self.reward is not None and isinstance(REWARD_PARTS[self.reward], LearnedRewardPart)

    @property
    def learner(self) -> LearnerKind:
        """Its kind of learner, which picks the training loop's strategy
        (``training.learners``): ``on_policy`` (batches of its own fresh episodes: TRPO),
        ``learned_reward`` (a replay-buffer agent on a reward learned in its update) or
        ``off_policy`` (a replay-buffer agent on an episode reward or the task reward)."""
        if AGENT_PARTS[self.agent].on_policy:
            return "on_policy"
        return "learned_reward" if self.learned else "off_policy"


def _td3_default(preset: str) -> TD3Config:
    return TD3Config.paper() if preset == "paper" else TD3Config.fast()


def _td3_for_run(config: TD3Config, horizon: int, fixed_horizon: bool) -> TD3Config:
    # Time augmentation draws a time-to-go for each critic sample: it needs the time feature,
    # which only fixed-horizon runs append to observations.
    return dataclasses.replace(
        config, time_augmentation=config.time_augmentation and fixed_horizon, max_time=horizon
    )


def _td7_for_run(config: TD7Config, horizon: int, fixed_horizon: bool) -> TD7Config:
    # As TD3's: the time feature exists only in fixed-horizon runs.
    return dataclasses.replace(
        config, time_augmentation=config.time_augmentation and fixed_horizon, max_time=horizon
    )


def _td7_checkpoints(config: TD7Config) -> CheckpointSchedule | None:
    if not config.policy_checkpoints:
        return None
    return CheckpointSchedule(
        config.checkpoint_max_episodes,
        config.checkpoint_early_updates,
        config.checkpoint_reset_weight,
    )


def _sac_learning(config: SACConfig, obs_dim: int, action_dim: int, max_action: float, setup):
    from ilfo.composition.learned import with_learned_reward

    return with_learned_reward(make_sac(config, obs_dim, action_dim, max_action), setup)


def _td3_learning(config: TD3Config, obs_dim: int, action_dim: int, max_action: float, setup):
    from ilfo.composition.learned import with_learned_reward

    return with_learned_reward(make_td3(config, obs_dim, action_dim, max_action), setup)


def _dacfo_defaults(env_id: str) -> dict[str, Any]:
    """The DACfO authors' code (opolo-code ``td3dacfo.py``, ``td3dacfo.yml``): TD3 with 400-300
    ReLU networks (Glorot initialisation), batch 100, Adam 3e-4 (1e-3 on Walker2d, for the
    discriminator too, which uses the agent's rate), tau 0.005, exploration noise 0.1, target
    smoothing 0.2 clipped at 0.5, policy delay 2, MSE loss, no time augmentation."""
    lr = 1e-3 if env_id.startswith("Walker2d") else 3e-4
    td3 = TD3Config(
        actor_hidden=(400, 300),
        critic_hidden=(400, 300),
        batch_size=100,
        exploration_noise=0.1,
        init_scheme="glorot",
        lr_actor=lr,
        lr_critic=lr,
    )
    return {"td3": td3, "discriminator": DiscriminatorConfig(lr=lr)}


def _opolo_defaults(env_id: str) -> dict[str, Any]:
    """The OPOLO authors' settings (opolo.yml): ``OPOLOConfig()``, and on Hopper lr 1e-4,
    alpha 0.01, pi_reg_coef 0.01; the discriminator learns at the agent's rate."""
    opolo = OPOLOConfig.hopper() if env_id.startswith("Hopper") else OPOLOConfig()
    return {"opolo": opolo, "discriminator": DiscriminatorConfig(lr=opolo.lr)}


AGENT_PARTS: dict[str, AgentPart] = {
    "td3": AgentPart(
        config=TD3Config,
        make=make_td3,
        make_learning=_td3_learning,
        default=_td3_default,
        for_run=_td3_for_run,
        title="TD3/DDPG agent",
        description=(
            "Defaults: the --preset's (paper | fast, shown as 'paper X, fast Y' where they "
            "differ); a flag here changes that one setting of the preset. oops-ddpg then applies "
            "DDPG's changes (one critic, no target smoothing, policy delay 1); gaifo-td3 starts "
            "from the DACfO authors' settings instead of the preset's. Set by the "
            "trainer: max_time (the episode horizon); time augmentation applies only where "
            "observations carry the time feature (fixed-horizon runs)."
        ),
        set_by_trainer=("max_time",),
    ),
    "td7": AgentPart(
        config=TD7Config,
        make=make_td7,
        default=lambda preset: TD7Config() if preset == "paper" else TD7Config.fast(),
        for_run=_td7_for_run,
        policy_checkpoints=_td7_checkpoints,
        title="TD7 agent",
        description=(
            "Defaults: --preset paper is the TD7 authors' (sfujim/TD7: widths 256, batch 256), "
            "fast is every width 128 and batch 100 (one CPU core); LAP as its uniform-sampling "
            "equivalent, the PAL loss; evaluations of the authors' policy checkpoints "
            "(--no-td7-policy-checkpoints: of the policy as trained). Set by the trainer: "
            "max_time (the episode horizon); time augmentation applies only in fixed-horizon "
            "runs."
        ),
        set_by_trainer=("max_time",),
    ),
    "sac": AgentPart(
        config=SACConfig,
        make=make_sac,
        default=lambda preset: SACConfig(),
        make_learning=_sac_learning,
        for_run=lambda config, horizon, fixed_horizon: config,
        title="SAC agent",
        description="Defaults: Haarnoja et al. 2018.",
    ),
    "opolo": AgentPart(
        config=OPOLOConfig,
        make=None,
        make_learning=make_opolo,
        default=lambda preset: OPOLOConfig(),
        for_run=lambda config, horizon, fixed_horizon: config,
        title="OPOLO agent",
        description="Defaults: the authors' code (opolo.yml; Hopper: lr 1e-4, alpha 0.01, "
        "pi-reg-coef 0.01).",
    ),
    "trpo": AgentPart(
        config=TRPOConfig,
        make=make_trpo,
        default=lambda preset: TRPOConfig(),
        for_run=lambda config, horizon, fixed_horizon: config,
        on_policy=True,
        title="TRPO agent (on-policy)",
        description="Defaults: the SIL authors' TRPO (Khrylx/PyTorch-RL as SIL ran it, its "
        "Fisher-vector product included), and a KL check in the line search (ilfo's). It "
        "learns from batches of its own episodes: --start-steps and --replay-capacity do not "
        "apply, and --updates-per-step other than 1 is an error.",
    ),
}
"""The agents, by the name of their ``TrainConfig`` field."""


def _firl_defaults(env_id: str) -> dict[str, Any]:
    """The f-IRL authors' MuJoCo configs: SAC 256-256, Adam 1e-3, fixed temperature 0.2, batch
    100, tau 0.005, gamma 0.99; on Ant a 128-128 reward network and 6 discriminator blocks."""
    sac = SACConfig(
        batch_size=100,
        lr_actor=1e-3,
        lr_critic=1e-3,
        init_temperature=0.2,
        autotune=False,
    )
    ant = env_id.startswith("Ant")
    firl = FIRLConfig(reward_hidden=(128, 128), disc_blocks=6) if ant else FIRLConfig()
    return {"sac": sac, "firl": firl}


def _firl_rollouts(config: FIRLConfig) -> Any:
    from ilfo.composition.learned import RolloutPlan

    return RolloutPlan(config.iteration_steps, config.rollouts)


def _discriminator_schedule(config: DiscriminatorConfig) -> Any:
    from ilfo.composition.learned import RewardSchedule

    return RewardSchedule(config.update_every, config.updates)


REWARD_PARTS: dict[str, RewardPart | LearnedRewardPart] = {
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
        description="Defaults: ilfo's PWIL-(s); --pwil-subsample 20 and --pwil-kernel-dim "
        "|S|+|A| are PWIL's own code. Set by the trainer: seed.",
        set_by_trainer=("seed",),
    ),
    "sil": RewardPart(
        config=SILConfig,
        make=SIL,
        learns_per_batch=True,
        title="SIL-(s,s') reward (adversarial critic)",
        description="Defaults: the SIL authors' code (docs/notes/sil-spec.md). Set by the "
        "trainer: seed.",
        set_by_trainer=("seed",),
    ),
    "oops_adv": RewardPart(
        config=AdversarialOOPSConfig,
        make=AdversarialOOPS,
        title="OOPS_adv reward (OOPS with SIL's adversarial cost)",
        description="Defaults: OOPS's coupling and scale, SIL's critic; the critic's schedule "
        "is ilfo's (the paper gives none). Set by the trainer: seed.",
        set_by_trainer=("seed",),
    ),
    "discriminator": LearnedRewardPart(
        config=DiscriminatorConfig,
        make=Discriminator,
        schedule=_discriminator_schedule,
        title="(s, s') discriminator reward",
        description="Defaults: the OPOLO authors' code (MuJoCo).",
    ),
    "firl": LearnedRewardPart(
        config=FIRLConfig,
        make=FIRL,
        schedule=lambda config: None,
        rollouts=_firl_rollouts,
        title="f-IRL (FKL) reward",
        description="Defaults: the authors' MuJoCo configs (Ant: reward 128-128, 6 blocks).",
    ),
}
"""The imitation rewards (episode and learned), by the name of their ``TrainConfig`` field."""

RECIPES: tuple[Recipe, ...] = (
    Recipe("oops-td3", "td3", "oops", "OOPS reward + TD3 with the PAL critic loss (the paper)"),
    Recipe("oops-ddpg", "td3", "oops", "OOPS reward + DDPG", adapt_agent=ddpg_config),
    Recipe("oops-sac", "sac", "oops", "OOPS reward + SAC"),
    Recipe("oops-td7", "td7", "oops", "OOPS reward + TD7 (SALE encoders, PAL/LAP, Fujimoto 2023)"),
    Recipe(
        "pwil-td3",
        "td3",
        "pwil",
        "PWIL-(s) reward + TD3 (the paper's PWIL baseline)",
        # PWIL's reward is always positive, so in its authors' code (standard episodes) a fall
        # that ends the episode forfeits the rest: staying up pays. With termination ignored
        # nothing does: Hopper 0.35 of the expert at 1M on the fixed horizon, 1.01 on standard
        # episodes (docs/results.md). Its runs before 2026-12-05 trained on the fixed horizon
        # (``training.migrations`` reads their records so).
        fixed_horizon=False,
    ),
    Recipe(
        "oops-adv-td3",
        "td3",
        "oops_adv",
        "OOPS_adv: OOPS with SIL's learned adversarial cosine cost + TD3 (the paper's Table 4)",
    ),
    Recipe(
        "sil",
        "trpo",
        "sil",
        "SIL-(s,s'): Sinkhorn imitation with an adversarial critic's cost + TRPO (Papagiannis "
        "& Li)",
        # Its reward is -2 c_t + 4 / T over a running std with no mean subtracted: with T fixed
        # at the horizon every reward clips at +10 (docs/reproduction.md); the authors' code
        # ends episodes at falls.
        fixed_horizon=False,
    ),
    Recipe(
        "gaifo-td3",
        "td3",
        "discriminator",
        "GAIfO/DACfO: an (s, s') discriminator's reward + TD3 (the OPOLO authors' td3dacfo)",
        part_defaults=_dacfo_defaults,
    ),
    Recipe(
        "opolo",
        "opolo",
        "discriminator",
        "OPOLO: discriminator reward, DICE critic, inverse-dynamics regularised actor (Zhu 2020)",
        part_defaults=_opolo_defaults,
    ),
    Recipe(
        "firl-fkl",
        "sac",
        "firl",
        "f-IRL (FKL): a state-only reward network by state-marginal matching + SAC (Ni 2020)",
        part_defaults=_firl_defaults,
        # The authors' SAC ends episodes at falls, where its entropy bonus makes staying up pay;
        # with termination ignored, the learned r(s) is too flat beside temperature 0.2 and the
        # policy stays near random on the floor (docs/results.md, f-IRL on Hopper).
        fixed_horizon=False,
        start_steps=1000,
    ),
    Recipe("td3", "td3", None, "TD3 on the task reward (no demos)"),
    Recipe("td7", "td7", None, "TD7 on the task reward (no demos)"),
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
