"""Expert policies: export a trained run as a shipped expert, load it, and collect demonstrations.

A shipped expert lives in ``data/experts/<env_id>/``:
  ``policy.msgpack``  the actor's parameters and observation normaliser (flax serialization)
  ``expert.json``     how to rebuild the policy (the run's TrainConfig) and its training record
  ``demos.npz``       demonstrations (ilfo npz: observations, with actions and rewards kept for
                      analysis only)
  ``card.json``       env id, algorithm, steps trained, seed, date, return mean and std over the
                      demos, sha256 of each file
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import time
import warnings
from pathlib import Path
from typing import Any

import flax.serialization
import numpy as np

from ilfo import demos as demo_io
from ilfo.agents import Policy, policy_of
from ilfo.envs import CONTACT_FORCE_DIMS, drop_contact_forces, make_env, termination_is_finish
from ilfo.files import file_sha256, load_msgpack
from ilfo.paper import paper_expert_returns
from ilfo.paths import DATA_DIR
from ilfo.training import (
    BEST_POLICY_FILE,
    BEST_POLICY_INFO,
    Agent,
    TrainConfig,
    config_from_dict,
    env_info,
    load_run_policy,
    make_agent,
    policy_actions,
    read_run_config,
    rollout_policy,
    score_policy,
)
from ilfo.training.config import check_eval_episodes
from ilfo.training.migrations import config_record, upgrade_run_config

POLICY_FILE, EXPERT_FILE, DEMOS_FILE, CARD_FILE = (
    "policy.msgpack",
    "expert.json",
    "demos.npz",
    "card.json",
)
EXPERT_FILES = frozenset({POLICY_FILE, EXPERT_FILE, DEMOS_FILE, CARD_FILE})
"""What an expert directory holds (and an export replaces)."""
CARD_EVAL_EPISODES = 10
"""Evaluation episodes on a card (its ``eval_return_mean`` and ``eval_return_std``)."""
EVAL_FIRST_SEED = 1000
"""First seed of expert evaluations: unlike the demos' (0, 1, ...)."""


PAPER_EXPERT_RETURNS: dict[str, float] = paper_expert_returns()
"""The paper's experts' mean returns (under its Tables 1 and 2: data/paper/results.json), the
targets of ilfo's experts; each card says how far its expert got."""

EXPERT_REWARD_SCALES: dict[str, float] = {
    "MinitaurBulletEnv-v0": 16.0,
    "MinitaurBulletDuckEnv-v0": 16.0,
}
"""SAC reward scales of ``ilfo expert train`` where 1 learns too little: Minitaur's per-step
rewards are ~0.01 (an expert's return is ~12 over 1,000 steps), which the entropy bonus swamps
(Minitaur at 1: a best evaluation of 0.5 in 485k steps; at 16: 12 by 160k). 16 = 2**4,
ElegantRL's setting for SAC on Minitaur. Every other env: 1."""


def expert_reward_scale(env_id: str) -> float:
    """The default SAC reward scale of an expert for ``env_id`` (see EXPERT_REWARD_SCALES)."""
    return EXPERT_REWARD_SCALES.get(env_id, 1.0)


def expert_dir(env_id: str) -> Path:
    """Where the shipped expert of ``env_id`` lives."""
    return DATA_DIR / "experts" / env_id


@dataclasses.dataclass(frozen=True)
class ExpertPolicy:
    """A deterministic policy rebuilt from an exported expert."""

    config: TrainConfig
    agent: Agent
    policy: Policy
    horizon: int

    @property
    def sees_all_columns(self) -> bool:
        """Whether the policy observes all of its env's observation columns (not: an Ant-v5 or
        Humanoid-v5 expert trained without the contact forces; envs without them resolve to
        True)."""
        return self.config.observes_contact_forces

    def observe(self, observations: np.ndarray) -> np.ndarray:
        """What the policy sees of the env's full observations (..., d): all of them, or those
        without the contact forces."""
        if self.sees_all_columns:
            return observations
        return drop_contact_forces(observations, self.config.env)

    def rollout(self, seed: int) -> Any:
        """One deterministic fixed-horizon episode (a ``train.Rollout``) in the env with all its
        observation columns, whatever the policy sees of them: demos keep the full state, and
        a run can imitate it with or without the contact forces."""
        env = make_env(self.config.env, True, horizon=self.horizon)
        observe = None if self.sees_all_columns else self.observe
        try:
            return rollout_policy(
                env, self.agent, self.policy, self.horizon, seed=seed, observe=observe
            )
        finally:
            env.close()


def export_expert(
    run_dir: str | Path, out_dir: str | Path | None = None, which: str = "best"
) -> Path:
    """Export a run's policy (actor and normaliser only) as an expert.

    ``which``: ``best`` (the policy of the run's best evaluation, the usual choice for SAC, whose
    evaluations swing between checkpoints) or ``latest`` (the last checkpoint's).
    """
    if which not in ("best", "latest"):
        raise ValueError(f"which must be 'best' or 'latest', got {which!r}")
    run_dir = Path(run_dir)
    best_info = run_dir / BEST_POLICY_INFO
    if which == "best" and best_info.is_file():
        run = load_run_policy(run_dir, "best")
        chosen = {"policy": "best", **json.loads(best_info.read_text())}
    else:  # the newest checkpoint's policy, step and evaluation
        if which == "best":
            warnings.warn(
                f"{run_dir} has no {BEST_POLICY_INFO} (no evaluation kept a best policy): "
                "exporting its latest checkpoint's policy",
                stacklevel=2,
            )
        run = load_run_policy(run_dir, "latest")
        ckpt = run.checkpoint
        assert ckpt is not None  # "latest" reads a checkpoint
        loop = ckpt.loop
        chosen = {"policy": "latest", "step": loop.step, "elapsed": loop.elapsed, **loop.last_eval}
    config = run.config
    out = Path(out_dir) if out_dir else expert_dir(config.env)
    out.mkdir(parents=True, exist_ok=True)
    if run.source == BEST_POLICY_FILE:  # the file as the run wrote it
        policy_bytes = (run_dir / BEST_POLICY_FILE).read_bytes()
    else:
        policy_bytes = flax.serialization.to_bytes(run.policy)
    (out / POLICY_FILE).write_bytes(policy_bytes)
    record = {
        "train_config": config_record(dataclasses.asdict(config)),
        "steps_trained": chosen["step"],
        "hours_trained": round(chosen["elapsed"] / 3600, 3),
        "horizon": run.env.horizon,
        "source_run": run_dir.name,
        "exported": chosen,
    }
    (out / EXPERT_FILE).write_text(json.dumps(record, indent=2) + "\n")
    return out


def _check_replaceable(out: Path) -> None:
    """Refuse an ``out`` that an export would wrongly replace: a file, or a directory holding
    anything but an expert's own files (an export replaces the directory whole)."""
    if not out.exists():
        return
    if not out.is_dir():
        raise FileExistsError(f"{out} is a file: the expert directory must be a new directory")
    others = sorted(p.name for p in out.iterdir() if p.name not in EXPERT_FILES)
    if others:
        raise FileExistsError(
            f"{out} holds other files than an expert's ({', '.join(others[:5])}"
            f"{', ...' if len(others) > 5 else ''}), which the export would delete: choose a "
            "new directory, or an expert directory to replace"
        )


def export_expert_with_demos(
    run_dir: str | Path,
    out_dir: str | Path | None,
    which: str,
    num_demos: int,
    skip_falls: bool = True,
    note: str | None = None,
) -> tuple[Path, dict[str, Any]]:
    """Export, collect ``num_demos`` demos and write the card, all or nothing.

    Everything is built in a temporary sibling directory that replaces ``out_dir`` (default
    ``data/experts/<env>``) only once complete, so a failure (e.g. an expert that falls in
    every episode) leaves a shipped expert as it was and no half-written one. Returns the
    expert directory and its card (``note``: see ``write_card``).
    """
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir else expert_dir(read_run_config(run_dir)["env"])
    _check_replaceable(out)
    staging = out.with_name(f".{out.name}.export-tmp")
    shutil.rmtree(staging, ignore_errors=True)
    try:
        export_expert(run_dir, staging, which=which)
        collect_demos(load_expert(staging), num_demos, staging / DEMOS_FILE, skip_falls=skip_falls)
        card = write_card(staging, note=note)
        old = out.with_name(f".{out.name}.export-old")
        shutil.rmtree(old, ignore_errors=True)
        if out.exists():
            os.replace(out, old)
        os.replace(staging, out)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out, card


def load_expert(path: str | Path) -> ExpertPolicy:
    """Load an exported expert from its directory (or an env id with a shipped expert)."""
    path = Path(path)
    if not path.is_dir() and (expert_dir(str(path)) / EXPERT_FILE).is_file():
        path = expert_dir(str(path))
    if not (path / EXPERT_FILE).is_file() or not (path / POLICY_FILE).is_file():
        raise FileNotFoundError(f"no expert at {path} (needs {EXPERT_FILE} and {POLICY_FILE})")
    record_path = path / EXPERT_FILE
    try:
        record = json.loads(record_path.read_text(encoding="utf-8"))
        raw_config, horizon = dict(record["train_config"]), int(record["horizon"])
    except (ValueError, KeyError, TypeError) as err:
        raise ValueError(f"{record_path} is not a readable expert record ({err})") from None
    config = config_from_dict(upgrade_run_config(raw_config, record_path), record_path)
    env = make_env(config.env, True, horizon=horizon, contact_forces=config.observes_contact_forces)
    try:  # only its shapes are needed; a PyBullet env holds a physics client until closed
        agent = make_agent(config, env_info(env, config.env), demos=None)
    finally:
        env.close()
    template = policy_of(agent.functions.init(config.seed))
    policy = load_msgpack(template, path / POLICY_FILE, "expert policy")
    return ExpertPolicy(config, agent, policy, horizon)


def collect_demos(
    expert: ExpertPolicy,
    num_episodes: int,
    out: str | Path,
    first_seed: int = 0,
    skip_falls: bool = True,
) -> list[demo_io.Episode]:
    """Deterministic full-length expert rollouts, saved to ``out`` (ilfo npz).

    Episodes run on seeds ``first_seed``, ``first_seed + 1``, ... With ``skip_falls`` an episode
    in which the environment reports a fall (termination, ignored in these fixed-horizon
    rollouts) is not kept and the next seed is tried: a demonstration should show the task done.
    The kept and the skipped seeds are recorded in the file's provenance, and so are the kept
    seeds whose episode has a fall (``skip_falls=False``: an expert that falls, shipped as the
    best reached). Where termination marks the task completed (BipedalWalker passing the end of
    its course, ``envs.termination_is_finish``), the episode is kept at full length, as the
    paper's code keeps it (the walker walks on past the finish; learner episodes run the same
    horizon), and the steps the environment reported as terminated are recorded
    (``Episode.terminated``), so the demo's ``task_score`` counts them as 0, as the evaluation
    does.

    Raises:
        ValueError: ``num_episodes`` < 1, ``first_seed`` < 0, or fewer than ``num_episodes``
            episodes without a fall in ``3 * num_episodes`` seeds (nothing is written).

    Warns where the seeds reach ``EVAL_FIRST_SEED``, where the expert's card is evaluated.
    """
    if num_episodes < 1:
        raise ValueError(f"need at least one episode, got {num_episodes}")
    if first_seed < 0:
        raise ValueError(f"seeds must be >= 0, got {first_seed}")
    episodes: list[demo_io.Episode] = []
    seeds: list[int] = []
    skipped: list[int] = []
    kept_falls: list[int] = []
    seed, last_seed = first_seed, first_seed + 3 * num_episodes
    while len(episodes) < num_episodes:
        if seed == last_seed:
            raise ValueError(
                f"the expert fell in {len(skipped)} of {seed - first_seed} episodes (seeds "
                f"{first_seed}-{seed - 1}): only {len(episodes)} of the {num_episodes} demos "
                "asked for are without a fall. Train it further, or keep the falls "
                "(--keep-falls / skip_falls=False)."
            )
        rollout = expert.rollout(seed=seed)
        ends = np.flatnonzero(rollout.env_terminated)
        fell = ends.size > 0 and not termination_is_finish(
            expert.config.env, rollout.rewards[ends[0]]
        )
        if skip_falls and fell:
            skipped.append(seed)
        else:
            if fell:
                kept_falls.append(seed)
            actions = policy_actions(
                expert.agent, expert.policy, expert.observe(rollout.observations), expert.horizon
            )
            episodes.append(
                demo_io.Episode(
                    rollout.observations, actions, rollout.rewards, rollout.env_terminated
                )
            )
            seeds.append(seed)
        seed += 1
    if seeds[-1] >= EVAL_FIRST_SEED:
        warnings.warn(
            f"the demos' seeds ({seeds[0]}-{seeds[-1]}) reach the expert evaluations' (from "
            f"{EVAL_FIRST_SEED}): an expert card's return (`ilfo expert export`, `ilfo expert "
            "eval`) is then measured partly on the demos' own starts",
            stacklevel=2,
        )
    demo_io.save(
        out,
        episodes,
        expert.config.env,
        provenance={
            "expert_algo": expert.config.algo,
            "seeds": seeds,
            "skipped_seeds_with_a_fall": skipped,
            "kept_seeds_with_a_fall": kept_falls,
            "fixed_horizon": True,
            "horizon": expert.horizon,
            "deterministic": True,
            "created": time.strftime("%Y-%m-%d"),
        },
    )
    return episodes


def paper_comparison(env_id: str, return_mean: float) -> dict[str, Any]:
    """Card fields comparing an expert's demo return with the paper's expert (None if the paper
    had no expert for ``env_id``)."""
    target = PAPER_EXPERT_RETURNS.get(env_id)
    return {
        "paper_expert_return": target,
        "fraction_of_paper_expert": None if target is None else round(return_mean / target, 3),
    }


def write_card(
    directory: str | Path, eval_episodes: int = CARD_EVAL_EPISODES, note: str | None = None
) -> dict[str, Any]:
    """Write ``card.json`` for an expert directory with policy, expert.json and demos.

    Besides the demos' return (demos without a fall, unless kept), the card records the
    expert's standard return over ``eval_episodes`` evaluation episodes on other seeds, falls
    included: how reliable the expert is, which the demos alone do not show. ``note``: a
    sentence for the reader (None for none), e.g. that an expert short of the paper's is
    shipped as the best reached, and why.
    """
    directory = Path(directory)
    record = json.loads((directory / EXPERT_FILE).read_text())
    data = demo_io.load(directory / DEMOS_FILE)
    returns = np.array([e.task_score for e in data.episodes])
    cfg = upgrade_run_config(record["train_config"], directory / EXPERT_FILE)
    card = {
        "env_id": cfg["env"],
        "algorithm": cfg["algo"],
        "steps_trained": record["steps_trained"],
        "hours_trained": record.get("hours_trained"),
        "seed": cfg["seed"],
        # A stricter torso angle range than the env's during training (ilfo expert train
        # --healthy-angle-range); demos and evaluations use the env's own range.
        "trained_healthy_angle_range": cfg.get("healthy_angle_range"),
        # Ant-v5, Humanoid-v5: False for an expert that acts without the contact forces (ilfo
        # expert train --no-contact-forces); its demos still hold the full observation. None
        # on envs without them.
        "observes_contact_forces": cfg["contact_forces"] is not False
        if cfg["env"] in CONTACT_FORCE_DIMS
        else None,
        "date": time.strftime("%Y-%m-%d"),
        "num_demos": len(data.episodes),
        "demo_lengths": [int(len(e.observations) - 1) for e in data.episodes],
        "return_mean": float(returns.mean()),
        "return_std": float(returns.std()),
        **paper_comparison(cfg["env"], float(returns.mean())),
        "demo_seeds": data.provenance.get("seeds"),
        "demo_seeds_skipped_for_a_fall": data.provenance.get("skipped_seeds_with_a_fall", []),
        # Demos kept although the expert fell in them (export --keep-falls): their task score
        # stops at the fall, so the card's return is what the expert reaches, falls included.
        "demo_seeds_with_a_fall": data.provenance.get("kept_seeds_with_a_fall", []),
        **card_evaluation(directory, eval_episodes),
        "note": note,
        "sha256": {
            name: file_sha256(directory / name) for name in (POLICY_FILE, EXPERT_FILE, DEMOS_FILE)
        },
    }
    (directory / CARD_FILE).write_text(json.dumps(card, indent=2) + "\n")
    return card


def card_evaluation(directory: str | Path, episodes: int = CARD_EVAL_EPISODES) -> dict[str, Any]:
    """The card's evaluation fields: standard return (which stops at the first fall) over
    ``episodes`` deterministic episodes on seeds from ``EVAL_FIRST_SEED``, unlike the demos'."""
    result = evaluate_expert(directory, episodes)
    return {
        "eval_episodes": episodes,
        "eval_first_seed": EVAL_FIRST_SEED,
        "eval_return_mean": result["return_mean"],
        "eval_return_std": result["return_std"],
    }


def evaluate_expert(
    path: str | Path, episodes: int, first_seed: int = EVAL_FIRST_SEED
) -> dict[str, Any]:
    """Mean and std of an expert's fixed-horizon score and standard return over ``episodes``,
    from 1 to ``training.config.MAX_EVAL_EPISODES`` (as a run's evaluation)."""
    check_eval_episodes(episodes, "--episodes")
    expert = load_expert(path)
    env = make_env(
        expert.config.env,
        True,
        horizon=expert.horizon,
        contact_forces=expert.config.observes_contact_forces,
    )
    seeds = [first_seed + k for k in range(episodes)]
    try:
        scored = score_policy(env, expert.agent, expert.policy, expert.horizon, seeds)
    finally:
        env.close()
    return {
        "env_id": expert.config.env,
        "episodes": episodes,
        "score_mean": float(np.mean(scored.scores)),
        "score_std": float(np.std(scored.scores)),
        "return_mean": float(np.mean(scored.returns)),
        "return_std": float(np.std(scored.returns)),
    }
