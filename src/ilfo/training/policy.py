"""A finished or running run's policy, read from its run directory: the agent its config builds,
with the parameters of its final, best or latest policy."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ilfo.agents import Policy, policy_of
from ilfo.agents.policy_checkpoints import evaluation_policy
from ilfo.files import load_msgpack
from ilfo.training.build import Agent, EnvInfo, env_info, make_agent, make_run_env
from ilfo.training.checkpoint import Checkpoint, load_checkpoint
from ilfo.training.config import TrainConfig, config_from_dict
from ilfo.training.migrations import read_run_config
from ilfo.training.run_dir import (
    BEST_POLICY_FILE,
    CONFIG_FILE,
    FINAL_POLICY_FILE,
    latest_checkpoint,
)


@dataclass(frozen=True)
class RunPolicy:
    """A run's policy, with what it takes to act with it (no trainer, no replay buffer)."""

    config: TrainConfig
    env: EnvInfo
    agent: Agent
    policy: Policy
    source: str
    """Where it came from: ``policy.msgpack``, ``best_policy.msgpack`` or ``latest
    checkpoint``."""
    checkpoint: Checkpoint | None = None
    """The checkpoint it was read from (its counters and evaluations; no replay buffer)."""

    def eval_env(self, render_mode: str | None = None) -> Any:
        """An environment as the run's evaluations used: fixed-horizon episodes of the run's
        horizon, its healthy angle range."""
        return make_run_env(self.config, True, horizon=self.env.horizon, render_mode=render_mode)


def load_run_policy(run_dir: str | Path, which: str = "final") -> RunPolicy:
    """A run's policy: ``final`` (``policy.msgpack``, written when the run finished, else the
    newest checkpoint's), ``best`` (``best_policy.msgpack``, the best-evaluated so far) or
    ``latest`` (the newest checkpoint's). Each is the policy the run evaluates: TD7's
    checkpoint policy where it has one. Clear errors for what is missing or damaged."""
    if which not in ("final", "best", "latest"):
        raise ValueError(f"which must be 'final', 'best' or 'latest', got {which!r}")
    run_dir = Path(run_dir)
    config = config_from_dict(read_run_config(run_dir), run_dir / CONFIG_FILE)
    # The run's environment, built only to read its spaces and horizon.
    env = env_info(make_run_env(config, config.uses_fixed_horizon), config.env)
    agent = make_agent(config, env, demos=None)  # a template: its state is read from files
    template = agent.functions.init(config.seed)
    file = {"final": FINAL_POLICY_FILE, "best": BEST_POLICY_FILE}.get(which)
    if which == "best" and not (run_dir / BEST_POLICY_FILE).is_file():
        raise FileNotFoundError(f"{run_dir} has no {BEST_POLICY_FILE} (no evaluation yet)")
    if file is not None and (run_dir / file).is_file():
        policy = load_msgpack(policy_of(template), run_dir / file, "policy")
        return RunPolicy(config, env, agent, policy, file)
    ckpt = latest_checkpoint(run_dir)
    if ckpt is None:
        raise FileNotFoundError(f"{run_dir} has neither {FINAL_POLICY_FILE} nor a checkpoint")
    loaded = load_checkpoint(ckpt, template, buffer_dims=None)
    # The policy the run evaluates (TD7's checkpoint policy where it has one).
    policy = evaluation_policy(loaded.loop.policy_checkpoint, loaded.agent_state)
    return RunPolicy(config, env, agent, policy, "latest checkpoint", loaded)
