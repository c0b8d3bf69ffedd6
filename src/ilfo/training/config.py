"""``TrainConfig``: one training run, every setting typed and documented (each field is a flag of
``ilfo train``), and ``config_from_dict`` to read one back from a file."""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from ilfo.agents import SACConfig, TD3Config
from ilfo.agents.td7 import TD7Config
from ilfo.agents.trpo import TRPOConfig
from ilfo.algos import (
    AGENT_PARTS,
    ALGOS,
    PART_CONFIGS,
    REWARD_PARTS,
    Recipe,
    algos_using,
    recipe,
)
from ilfo.composition.opolo import OPOLOConfig
from ilfo.config import dataclass_from_dict, flag_name
from ilfo.envs.make import CONTACT_FORCE_DIMS
from ilfo.ranges import INT32_MAX, SettingError, check_fields, count, non_negative, rng_seed
from ilfo.rewards import DiscriminatorConfig, FIRLConfig, OOPSConfig, PWILConfig
from ilfo.rewards.oops_adv import AdversarialOOPSConfig
from ilfo.rewards.sil import SILConfig

DEFAULT_START_STEPS = 10_000
"""Uniformly random steps before the policy acts, where neither the run nor its algo says (the
OOPS paper's code)."""

MAX_EVAL_EPISODES = 10_000
"""The most episodes one evaluation runs (``eval_episodes``, ``ilfo eval --episodes``): each is
a whole fixed-horizon episode (1,000 steps in the paper's envs), so 10,000 are hours of
rollouts per evaluation already; more is a typo (a billion's list of seeds alone took 23 GB
before the kernel killed the run, with no message)."""


def check_eval_episodes(episodes: int, setting: str) -> None:
    """A ValueError naming ``setting`` (the field or flag) where ``episodes`` is not an integer
    from 1 to ``MAX_EVAL_EPISODES``: the one check of an evaluation's number of episodes."""
    if isinstance(episodes, bool) or not isinstance(episodes, numbers.Integral):
        raise ValueError(f"{setting} must be an integer, got {episodes!r}")
    if not 1 <= episodes <= MAX_EVAL_EPISODES:
        raise ValueError(
            f"{setting} must be from 1 to {MAX_EVAL_EPISODES:,} (episodes per evaluation, each "
            f"a whole episode), got {episodes:,}"
        )


def part_flag(part: str, setting: str) -> str | None:
    """The ``ilfo train`` flag of field ``setting`` of part ``part`` (``--td3-batch-size``);
    None for the fields the trainer sets (no flag)."""
    if setting in {**AGENT_PARTS, **REWARD_PARTS}[part].set_by_trainer:
        return None
    return flag_name(setting, part)


if TYPE_CHECKING:  # a type checker cannot build a Literal from the registry: any name to it
    Algo = str
else:
    Algo = Literal[tuple(ALGOS)]
    """The names of ``ilfo.algos.ALGOS``, made from the registry (the CLI's ``--algo``
    choices)."""


@dataclass(frozen=True)
class TrainConfig:
    """One training run. Defaults: OOPS+TD3 on Hopper-v5 from one demo, as in the paper."""

    env: str = "Hopper-v5"
    """Gymnasium environment id."""
    algo: Algo = "oops-td3"
    """The algorithm, a recipe of ``ilfo.algos`` (its agent and reward); td3 and sac learn from
    the true task reward (no demos)."""
    demos: str | None = None
    """Demonstration file (.npz); omit it (None) for the env's shipped expert demos
    (data/experts/<env>/demos.npz)."""
    num_demos: int = count(1)
    """How many of the file's demos to imitate (the first N)."""
    steps: int = count(1_000_000)
    """Environment steps in total (random ones included)."""
    start_steps: int | None = count(None, low=0)
    """Uniformly random steps before the policy acts (off-policy agents only: TRPO acts from
    the first step); None: the algo's (``Recipe.start_steps``: firl-fkl 1,000, as its authors'
    code), else ``DEFAULT_START_STEPS`` (10,000, the paper's)."""
    updates_per_step: int = count(1)
    """Agent updates per environment step collected (the update-to-data ratio), run after each
    episode; 1 is the paper's. More spends compute to learn more from the same data. Off-policy
    agents only: other than 1 is an error for TRPO (sil), which learns once per batch
    (``--trpo-batch-steps``). ``steps`` times it is at most 2**31 - 1 (the agents' update
    counters are 32-bit)."""
    preset: Literal["paper", "fast"] = "paper"
    """Agent sizes: for TD3/DDPG paper (critics 1024-1024) or fast (critics 256-256); for TD7
    paper (the authors': widths 256, batch 256) or fast (widths 128, batch 100); the part's
    flags (--td3-*, --td7-*) change single settings."""
    seed: int = rng_seed()
    """Seed of everything: environment, exploration, networks, demo draws."""
    fixed_horizon: bool | None = None
    """Run every episode to the full horizon, ignoring termination (the paper); None: on for
    imitation (except sil and firl-fkl, off as their authors' code, and pwil-td3, off as
    measured: docs/results.md), off for true-reward algos."""
    horizon: int | None = count(None, note="none: the env's own")
    """Episode length; None: the environment's limit (1,000 for MuJoCo)."""
    healthy_angle_range: tuple[float, float] | None = None
    """Torso angle range (radians) outside which Hopper or Walker2d counts as fallen, in this
    run's training and evaluation episodes; None: the env's own ((-0.2, 0.2) for Hopper).
    Stricter ranges train experts with a margin from a fall; demos and the paper's scores always
    use the env's own range."""
    contact_forces: bool | None = None
    """Ant-v5 and Humanoid-v5: observe the bodies' contact forces (gymnasium's v5 observations
    end with them). False drops them from the learner's observations and from the demos'. None:
    off for imitation, as the paper's v2 tasks saw them (all zero: mujoco-py >= 2.0 left them
    unfilled; on Humanoid they are 98% of OOPS's distance once the learner has fallen,
    docs/benchmarks.md), on for the task reward (``ilfo expert train``'s experts observe them).
    Other envs have none to drop."""
    eval_every: int = count(5_000)
    """Evaluate every this many environment steps."""
    eval_episodes: int = count(10, high=MAX_EVAL_EPISODES, check=check_eval_episodes)
    """Deterministic episodes per evaluation (at most ``MAX_EVAL_EPISODES``, 10,000)."""
    best_by: Literal["score", "return"] = "score"
    """Which evaluation picks best_policy.msgpack: ``score`` (the paper's fixed-horizon score)
    or ``return`` (the standard return, which stops at the first fall: what an expert is judged
    by; ``ilfo expert train`` uses it)."""
    checkpoint_every: int = count(50_000)
    """Checkpoint every this many environment steps (and on Ctrl-C, and at the end)."""
    checkpoint_minutes: float = non_negative(10.0, note="0: off")
    """Also checkpoint when this many minutes of wall-clock time have passed since the last
    checkpoint (or the start), so that a crash loses at most that much of any run, short runs
    included; 0 turns the clock off (steps only)."""
    replay_capacity: int = count(1_000_000)
    """Replay buffer size in transitions (off-policy agents; TRPO keeps only its batch)."""
    out: str = "runs"
    """Parent directory of the run directory."""
    td3: TD3Config | None = None
    """TD3/DDPG agent (algos oops-td3, oops-ddpg, pwil-td3, td3); None: the preset's
    (``TD3Config.paper()`` or ``.fast()``). Whatever is given, the trainer sets ``max_time`` to
    the episode horizon, keeps ``time_augmentation`` only where observations carry the time
    feature (fixed-horizon runs), and applies ``ddpg_config`` for oops-ddpg."""
    td7: TD7Config | None = None
    """TD7 agent (algos oops-td7, td7); None: the preset's (``TD7Config()``, the authors', or
    ``TD7Config.fast()``). The trainer sets ``max_time`` and time augmentation as for TD3."""
    sac: SACConfig | None = None
    """SAC agent (algos oops-sac, firl-fkl, sac); None: ``SACConfig()``, Haarnoja et al.'s
    defaults (firl-fkl: the f-IRL authors' SAC)."""
    oops: OOPSConfig | None = None
    """OOPS rewarder (algos oops-*); None: the paper's defaults. Its ``seed`` is always replaced
    by this config's ``seed``, so that one seed sets a whole run (seed sweeps with a custom OOPS
    config stay seed sweeps)."""
    pwil: PWILConfig | None = None
    """PWIL rewarder (algo pwil-td3); None: the paper's defaults (``PWILConfig()``)."""
    opolo: OPOLOConfig | None = None
    """OPOLO agent (algo opolo); None: the authors' settings for the env (``OPOLOConfig()``,
    ``OPOLOConfig.hopper()`` on Hopper)."""
    discriminator: DiscriminatorConfig | None = None
    """The (s, s') discriminator whose reward gaifo-td3 and opolo learn from; None: the
    authors' settings (``DiscriminatorConfig()`` at the agent's learning rate)."""
    firl: FIRLConfig | None = None
    """f-IRL's reward (algo firl-fkl); None: the authors' settings for the env."""
    trpo: TRPOConfig | None = None
    """TRPO agent (algo sil), on-policy; None: the SIL authors' settings with a KL check in the
    line search (``TRPOConfig()``)."""
    sil: SILConfig | None = None
    """SIL-(s,s')'s reward (algo sil); None: the authors' settings (``SILConfig()``)."""
    oops_adv: AdversarialOOPSConfig | None = None
    """OOPS_adv's reward (algo oops-adv-td3); None: ``AdversarialOOPSConfig()``."""

    def __post_init__(self) -> None:
        algo = recipe(self.algo)
        for name, cls in PART_CONFIGS.items():  # dicts, as read back from config.json
            try:
                part = dataclass_from_dict(cls, getattr(self, name), name)
            except SettingError as err:
                raise err.within(name, part_flag(name, err.setting)) from None
            object.__setattr__(self, name, part)
        for name in PART_CONFIGS:
            if getattr(self, name) is not None and name not in (algo.agent, algo.reward):
                rewarder = f"the {algo.reward.upper()}" if algo.reward else "no"
                raise ValueError(
                    f"{name} settings (--{name.replace('_', '-')}-* flags) do not apply to "
                    f"algo {self.algo!r}, "
                    f"which uses the {algo.agent.upper()} agent and {rewarder} rewarder; "
                    f"{name} is for {', '.join(algos_using(name))}"
                )
        # Types and ranges, from the fields' declarations (ilfo.ranges), named with their flags.
        check_fields(self, flags="")
        if self.demos is not None and not algo.imitation:
            raise ValueError(
                f"demos (--demos) do not apply to algo {self.algo!r}: it learns from the task "
                f"reward, not from demonstrations; leave demos out, or choose an imitation algo"
            )
        if AGENT_PARTS[algo.agent].on_policy and self.updates_per_step != 1:
            # Ignored, it would make a sweep's updates-per-step comparison silently wrong.
            raise ValueError(
                f"updates_per_step does not apply to algo {self.algo!r}: its on-policy "
                f"{algo.agent.upper()} agent learns once per batch of its own episodes "
                f"(--{algo.agent}-batch-steps); leave it at 1"
            )
        if self.steps * self.updates_per_step > INT32_MAX:
            # The agents count their updates in int32 (``state.step``): past it the count wraps
            # to negative, and TD3's actor delay and TD7's target refresh lose their cadence.
            raise ValueError(
                f"steps * updates_per_step must be at most {INT32_MAX:,} (the agents count "
                f"their updates in 32-bit integers), got {self.steps:,} * "
                f"{self.updates_per_step:,} = {self.steps * self.updates_per_step:,} "
                f"(--steps, --updates-per-step)"
            )
        angles = self.healthy_angle_range
        if angles is not None and not angles[0] < angles[1]:
            raise ValueError(
                f"healthy_angle_range must be (low, high) with low < high, got {list(angles)}"
            )
        if self.contact_forces is False and self.env not in CONTACT_FORCE_DIMS:
            raise ValueError(
                f"--no-contact-forces applies to {', '.join(CONTACT_FORCE_DIMS)}, not {self.env}"
            )

    @property
    def recipe(self) -> Recipe:
        """The algorithm's registry entry (``ilfo.algos``): its agent and reward parts."""
        return ALGOS[self.algo]

    @property
    def imitation(self) -> bool:
        """Whether the algo learns from demos (True) or from the task reward (False)."""
        return self.recipe.imitation

    @property
    def uses_fixed_horizon(self) -> bool:
        """The resolved ``fixed_horizon``: as given, else the algo's (``Recipe.fixed_horizon``),
        else on for imitation and off for the task reward."""
        if self.fixed_horizon is not None:
            return self.fixed_horizon
        if self.recipe.fixed_horizon is not None:
            return self.recipe.fixed_horizon
        return self.imitation

    @property
    def observes_contact_forces(self) -> bool:
        """The resolved ``contact_forces``: as given, else ``default_contact_forces``."""
        if self.contact_forces is not None:
            return self.contact_forces
        return default_contact_forces(self.env, self.imitation)

    @property
    def random_steps(self) -> int:
        """The resolved ``start_steps``: as given, else the algo's (``Recipe.start_steps``),
        else ``DEFAULT_START_STEPS``."""
        if self.start_steps is not None:
            return self.start_steps
        if self.recipe.start_steps is not None:
            return self.recipe.start_steps
        return DEFAULT_START_STEPS

    def part_config(self, part: str) -> Any:
        """The config of part ``part`` (a field name: ``td3``, ``oops``, ...) as given, else its
        default (the recipe's ``part_defaults``, else the ``preset``'s, for an agent); a
        ``seed`` field is always this run's seed, so that one seed sets a whole run (seed
        sweeps with a custom config stay seed sweeps)."""
        given = getattr(self, part)
        if given is None and self.recipe.part_defaults is not None:
            given = self.recipe.part_defaults(self.env).get(part)
        if given is None:
            given = AGENT_PARTS[part].default(self.preset) if part in AGENT_PARTS else None
            given = PART_CONFIGS[part]() if given is None else given
        if any(f.name == "seed" for f in dataclasses.fields(given)):
            given = dataclasses.replace(given, seed=self.seed)
        return given

    def agent_config(
        self, horizon: int
    ) -> TD3Config | TD7Config | SACConfig | OPOLOConfig | TRPOConfig:
        """The agent's config exactly as the run builds it, for episodes of ``horizon`` steps:
        what the trainer sets (``AgentPart.for_run``: TD3's ``max_time`` is the horizon, time
        augmentation only where observations carry the time feature), then the recipe's change
        (``ddpg_config`` for oops-ddpg)."""
        algo = self.recipe
        config = AGENT_PARTS[algo.agent].for_run(
            self.part_config(algo.agent), horizon, self.uses_fixed_horizon
        )
        return config if algo.adapt_agent is None else algo.adapt_agent(config)

    def resolved(self, horizon: int) -> TrainConfig:
        """This config with its algo's part configs filled in as the run uses them, the others
        None. What a run's config.json records, so that it shows every setting and builds the
        same run even if presets change."""
        algo = self.recipe
        parts: dict[str, Any] = dict.fromkeys(PART_CONFIGS)
        parts[algo.agent] = self.agent_config(horizon)
        if algo.reward is not None:
            parts[algo.reward] = self.part_config(algo.reward)
        return dataclasses.replace(
            self,
            start_steps=self.random_steps,
            # Resolved, so that a later change of an algo's default episodes (f-IRL's was)
            # cannot change how a resumed run's episodes end.
            fixed_horizon=self.uses_fixed_horizon,
            # Recorded where the env has contact forces, so that a later default cannot change
            # what a resumed run observes; None elsewhere, where there is nothing to choose.
            contact_forces=self.observes_contact_forces
            if self.env in CONTACT_FORCE_DIMS
            else self.contact_forces,
            **parts,
        )


def default_contact_forces(env: str, imitation: bool) -> bool:
    """Whether a run on ``env`` observes the contact forces when its config leaves
    ``contact_forces`` None: not on Ant-v5 and Humanoid-v5 for ``imitation`` (the paper's v2
    tasks had them all zero), else yes (the task reward, and envs without them)."""
    return env not in CONTACT_FORCE_DIMS or not imitation


def imitation_drops_contact_forces(env_id: str, contact_forces: bool | None) -> bool:
    """Whether imitation compares ``env_id``'s states without their contact forces (``ilfo
    reward``, ``ilfo label``): ``contact_forces`` False, or None on an env whose imitation drops
    them by default. ValueError for False on an env without them."""
    if env_id not in CONTACT_FORCE_DIMS:
        if contact_forces is False:
            raise ValueError(
                f"--no-contact-forces applies to {', '.join(CONTACT_FORCE_DIMS)} demos, "
                f"not {env_id or 'unnamed'}'s"
            )
        return False
    if contact_forces is None:
        contact_forces = default_contact_forces(env_id, imitation=True)
    return not contact_forces


def preset_changes_agent(config: TrainConfig, horizon: int = 1000) -> bool:
    """Whether the other ``preset`` would build ``config``'s agent otherwise (TD3 and DDPG's
    network sizes; not SAC, OPOLO, or the baselines' authors' settings)."""
    other: Literal["paper", "fast"] = "fast" if config.preset == "paper" else "paper"
    return config.agent_config(horizon) != dataclasses.replace(config, preset=other).agent_config(
        horizon
    )


RESOLVED_BY_ENV_AND_ALGO = ("contact_forces", "fixed_horizon", "start_steps")
"""Settings that config.json records as its env and algo resolved them (``resolved``)."""


def settings_for_new_runs(settings: Mapping[str, Any], drop: tuple[str, ...]) -> dict[str, Any]:
    """A settings file's (or a finished run's config.json's) settings as the base of other
    runs: without the keys in ``drop`` (what the new runs set themselves: a sweep's axes, the
    output directory) and without parts that are None (config.json lists every part). A run's
    config.json records the contact forces, episodes and random steps as its env and algo
    resolved them, so dropping ``env`` or ``algo`` drops those too (the new pair's defaults
    apply)."""
    if any(key in settings and key in drop for key in ("env", "algo")):
        drop = (*drop, *RESOLVED_BY_ENV_AND_ALGO)
    return {
        key: value
        for key, value in settings.items()
        if key not in drop and not (key in PART_CONFIGS and value is None)
    }


def config_from_dict(raw: Mapping[str, Any], source: str | Path) -> TrainConfig:
    """A ``TrainConfig`` from a record ilfo wrote, in today's format (config.json, expert.json
    and a sweep's manifest are read through ``migrations``, which upgrades older ones); a
    ValueError names ``source`` and the setting at fault (an unknown key, a value of the wrong
    type)."""
    return _checked_config(raw, source)


def _checked_config(raw: Mapping[str, Any], source: str | Path) -> TrainConfig:
    """``TrainConfig(**raw)``, its errors naming ``source``."""
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


def config_from_settings(settings: Mapping[str, Any], source: str | Path) -> TrainConfig:
    """A ``TrainConfig`` from settings as a file or a sweep spec gives them: top-level fields,
    and for a part (``td3``, ``oops``, ...) a dict that changes single fields of the part's
    default for this run (the recipe's for the env, else the preset's), as the ``--td3-*``
    flags do; a whole part (a run's own config.json) reads back unchanged. A ValueError names
    ``source`` and the setting at fault."""
    parts = {k: v for k, v in settings.items() if k in PART_CONFIGS and isinstance(v, Mapping)}
    config = _checked_config({k: v for k, v in settings.items() if k not in parts}, source)
    changed = {}
    for name, given in parts.items():
        known = {f.name for f in dataclasses.fields(PART_CONFIGS[name])}
        unknown = sorted(set(given) - known)
        if unknown:
            raise ValueError(
                f"{source}: {name} has no setting(s) {', '.join(map(repr, unknown))}; "
                f"known: {', '.join(sorted(known))}"
            )
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in given.items()}
        try:
            changed[name] = dataclasses.replace(config.part_config(name), **values)
        except SettingError as err:
            raise ValueError(
                f"{source}: {err.within(name, part_flag(name, err.setting))}"
            ) from None
        except (TypeError, ValueError) as err:
            raise ValueError(f"{source}: {name}: {err}") from None
    try:
        return dataclasses.replace(config, **changed)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{source}: {err}") from None
