"""Labels of how a run was trained: its settings where they differ from ``ilfo train``'s
defaults for its env and algo (the paper's protocol), read from its ``config.json`` (as
``read_run_config`` reads it: in today's format).

``run_variant`` (its reward's settings and its observations) and ``training_settings`` (its
preset, steps, episodes, agent fields) are what ``ilfo report`` sets runs into cells by and
names in its ``settings`` column, and what ``ilfo plot`` draws separate curves by:
runs that differ in either are not seeds of one setting.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def run_variant(config: dict[str, Any], source: Path, variant: str | None = None) -> str | None:
    """A run's variant: ``variant`` (a sweep manifest's name for it) or, without one, its
    reward's settings that differ from its algo's defaults, joined with its observations'
    (``"no-contact-forces"``) where those differ; None for a run at the defaults."""
    if variant is None:
        variant = _reward_settings_variant(config, source)
    labels = (variant, _contact_forces_variant(config))
    return "+".join(label for label in labels if label) or None


def shared_settings(settings: Sequence[tuple[str, ...]]) -> tuple[str, ...]:
    """The labels (``training_settings``) that every one of ``settings`` has, in the order of
    the first."""
    shared = set.intersection(*(set(labels) for labels in settings)) if settings else set()
    return tuple(label for label in (settings[0] if settings else ()) if label in shared)


def _contact_forces_variant(config: dict[str, Any]) -> str | None:
    """ "contact-forces" or "no-contact-forces" for a run that observed Ant's or Humanoid's
    contact forces otherwise than ``ilfo train``'s default for its algo, else None."""
    from ilfo.algos import ALGOS
    from ilfo.envs.make import CONTACT_FORCE_DIMS
    from ilfo.training.config import default_contact_forces

    env, algo = config.get("env"), config.get("algo")
    if env not in CONTACT_FORCE_DIMS or algo not in ALGOS:
        return None
    default = default_contact_forces(env, ALGOS[algo].imitation)
    observed = config.get("contact_forces")
    observed = default if observed is None else bool(observed)
    if observed == default:
        return None
    return "contact-forces" if observed else "no-contact-forces"


def _reward_settings_variant(config: dict[str, Any], source: Path) -> str | None:
    """For a run of an imitation algo, the settings of its reward in which it differs from the
    algo's defaults for its env, as "pwil.subsample=20+pwil.kernel_dim=23"; None where it has
    none (the seed, which the trainer sets, is not a setting). A setting newer than the config
    reads back as its default (``training.migrations``: it keeps what older runs did)."""
    from ilfo.algos import ALGOS, REWARD_PARTS
    from ilfo.training.config import TrainConfig, config_from_dict

    recipe = ALGOS.get(str(config.get("algo")))
    if recipe is None or recipe.reward is None:
        return None
    run = config_from_dict(config, source)
    default = TrainConfig(env=run.env, algo=run.algo, seed=run.seed)
    given, usual = run.part_config(recipe.reward), default.part_config(recipe.reward)
    set_by_trainer = REWARD_PARTS[recipe.reward].set_by_trainer
    changed = [
        f"{recipe.reward}.{f.name}={setting_label(getattr(given, f.name))}"
        for f in dataclasses.fields(given)
        if f.name not in set_by_trainer and getattr(given, f.name) != getattr(usual, f.name)
    ]
    return "+".join(changed) or None


def training_settings(config: dict[str, Any], source: Path) -> tuple[str, ...]:
    """Labels of a run's training settings that differ from ``ilfo train``'s defaults for its
    env and algo: the preset, steps, updates per step, episodes, and its agent's fields. A
    config this version cannot read raises (a report leaves the run out and says why)."""
    from ilfo.algos import AGENT_PARTS
    from ilfo.training.config import TrainConfig, config_from_dict, preset_changes_agent

    run = config_from_dict(config, source)
    default = TrainConfig(env=run.env, algo=run.algo, seed=run.seed)
    agent = run.recipe.agent
    # Agents are compared as runs build them (config.json records them so: DDPG's TD3 changes,
    # the time augmentation of fixed-horizon runs), at the run's preset and episodes, which
    # their own labels name; the preset only where it changes the agent (not SAC, OPOLO or the
    # authors' settings of f-IRL and GAIfO).
    horizon = run.horizon or 1000
    alike = dataclasses.replace(default, preset=run.preset, fixed_horizon=run.uses_fixed_horizon)
    labels = []
    if run.preset != default.preset and preset_changes_agent(alike, horizon):
        labels.append(f"{run.preset} preset")
    if run.steps != default.steps:
        labels.append(f"{steps_label(run.steps)} steps")
    if run.updates_per_step != default.updates_per_step:
        labels.append(f"{run.updates_per_step} updates/step")
    if run.uses_fixed_horizon != default.uses_fixed_horizon:
        labels.append("fixed horizon" if run.uses_fixed_horizon else "standard episodes")
    replay = () if AGENT_PARTS[agent].on_policy else ("random_steps", "replay_capacity")
    for name in (*replay, "horizon", "healthy_angle_range"):
        if getattr(run, name) != getattr(default, name):
            labels.append(f"{name}={setting_label(getattr(run, name))}")
    if run.eval_episodes != default.eval_episodes:
        labels.append(f"{run.eval_episodes} evaluation episodes")
    given, usual = run.agent_config(horizon), alike.agent_config(horizon)
    set_by_trainer = AGENT_PARTS[agent].set_by_trainer
    labels += [
        f"{agent}.{f.name}={setting_label(getattr(given, f.name))}"
        for f in dataclasses.fields(given)
        if f.name not in set_by_trainer and getattr(given, f.name) != getattr(usual, f.name)
    ]
    return tuple(labels)


def steps_label(steps: int) -> str:
    """A step count as a label says it: 300k, 1.5M."""
    for size, suffix in ((1_000_000, "M"), (1_000, "k")):
        if steps >= size and steps % (size // 100) == 0:
            return f"{steps / size:g}{suffix}"
    return str(steps)


def setting_label(value: Any) -> str:
    """A setting's value as a label says it (floats short, sequences joined by "-")."""
    if isinstance(value, float):
        return format(value, "g")
    if isinstance(value, tuple | list):
        return "-".join(map(setting_label, value))
    return str(value)
