"""Training runs: a ``TrainConfig`` in, a run directory out.

A run directory (``ilfo train`` writes ``runs/<env>__<algo>__<seed>__<time>/``) holds
``config.json`` (every setting as the run used it), ``demos.json`` (an imitation run's demo
file, its sha256 and the demos' mean return: ``build.DemoSource``), ``metrics.csv`` and ``tb/``
(TensorBoard),
``checkpoints/`` (``checkpoint``), ``policy.msgpack`` (the final policy), ``best_policy.msgpack``
and ``best_policy.json`` (the best-evaluated policy, its step and scores) and
``learning_curve.png``.

Modules: ``config`` (``TrainConfig``), ``build`` (demos, agent, reward and environments from a
config, through the registry ``ilfo.algos``), ``rollout`` (episodes of a policy and their scores;
the one home of the time feature), ``loop`` (``Trainer``, ``LoopHooks``), ``checkpoint``,
``metrics`` (metrics.csv and TensorBoard), ``run_dir`` (the rules of a run directory),
``migrations`` (what a run writes says its format; an older run's records are read as
today's), ``policy`` (the one reader of a run's policy), ``run_labels`` (how a run was trained
otherwise than the defaults), ``plots``.
"""

from ilfo.training.build import (
    Agent,
    DemoSet,
    DemoSource,
    EnvInfo,
    default_demos_path,
    env_info,
    load_demo_set,
    load_demos,
    make_agent,
    make_envs,
    make_reward,
    network_normalizer,
    run_name,
)
from ilfo.training.checkpoint import Checkpoint, LoopState, load_checkpoint, save_checkpoint
from ilfo.training.config import (
    Algo,
    TrainConfig,
    config_from_dict,
    config_from_settings,
    settings_for_new_runs,
)
from ilfo.training.loop import LoopHooks, Trainer
from ilfo.training.metrics import METRIC_FIELDS, read_metrics
from ilfo.training.migrations import read_run_config, read_settings
from ilfo.training.plots import plot_runs
from ilfo.training.policy import RunPolicy, load_run_policy
from ilfo.training.rollout import (
    PolicyScores,
    Rollout,
    agent_observation,
    agent_observations,
    policy_actions,
    rollout_policy,
    score_policy,
)
from ilfo.training.run_dir import (
    BEST_POLICY_FILE,
    BEST_POLICY_INFO,
    FINAL_POLICY_FILE,
    RunDirInUse,
    RunLock,
    create_run_dir,
    latest_checkpoint,
)

__all__ = [
    "BEST_POLICY_FILE",
    "BEST_POLICY_INFO",
    "FINAL_POLICY_FILE",
    "METRIC_FIELDS",
    "Agent",
    "Algo",
    "Checkpoint",
    "DemoSet",
    "DemoSource",
    "EnvInfo",
    "LoopHooks",
    "LoopState",
    "PolicyScores",
    "Rollout",
    "RunDirInUse",
    "RunLock",
    "RunPolicy",
    "TrainConfig",
    "Trainer",
    "agent_observation",
    "agent_observations",
    "config_from_dict",
    "config_from_settings",
    "create_run_dir",
    "default_demos_path",
    "env_info",
    "latest_checkpoint",
    "load_checkpoint",
    "load_demo_set",
    "load_demos",
    "load_run_policy",
    "make_agent",
    "make_envs",
    "make_reward",
    "network_normalizer",
    "plot_runs",
    "policy_actions",
    "read_metrics",
    "read_run_config",
    "read_settings",
    "rollout_policy",
    "run_name",
    "save_checkpoint",
    "score_policy",
    "settings_for_new_runs",
]
