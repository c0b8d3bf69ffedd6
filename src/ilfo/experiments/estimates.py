"""What runs cost on one core: the measured rates that ``ilfo reproduce``'s plans and
``ilfo train``'s start summary estimate compute from (``run_core_seconds``, the one estimate
of a run): steps per second from ``rates.json`` (data that ``bench/rates.py`` writes from the
kept runs), and the other costs each with where and when it was measured."""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ilfo.algos import ALGOS
from ilfo.training.config import TrainConfig, preset_changes_agent

RATES_FILE = Path(__file__).with_name("rates.json")
"""The measured steps per second of one core, by algo and env: written by ``bench/rates.py``
from the kept runs' metrics.csv (each run pinned to one core beside another, evaluations
included), with the date, machine and commit of that measurement."""


@functools.cache
def measured_rates() -> Mapping[str, Any]:
    """``RATES_FILE``'s rates by algo: ``steps_per_s`` (the median over its kept runs), ``runs``
    and ``envs`` (the median per env)."""
    return json.loads(RATES_FILE.read_text())["algos"]


def steps_per_core_second(algo: str, env: str | None = None) -> float | None:
    """The measured rate of ``algo`` at the fast preset: on ``env`` where its runs include that
    env, else the median over all its runs; None for an algo with no kept run."""
    rates = measured_rates().get(algo)
    if rates is None:
        return None
    return rates["envs"].get(env, rates["steps_per_s"])


UPDATE_SHARE: dict[str, float] = {"fast": 0.7, "paper": 0.96}
"""For the estimate only: the share of an off-policy step's time spent in its update at one
update per step, by preset (``bench/train.py``; docs/benchmarks.md as of commit 446cbed: at the
fast preset the loop ran 1070, 624 and 361 steps/s at one, two and four updates per step; at the
paper preset the updates were 96% of a step). N updates per step cost (1 - share) + share * N
times as much. Measured on TD3 and used for every off-policy algo: an algo whose step goes
more to its reward (oops-adv-td3, opolo) is costed a little high."""


RUN_FIXED_CORE_SECONDS = 32.0
"""For the estimate only: one core's seconds that a run costs whatever its steps (each start
of one, a resume included): its process's imports, its envs and demos, JAX's compilation of
its programs and what else does not scale with its steps; nearly all of a tiny run. Measured
on one smoke run (``SMOKE_CONFIG``: 400 steps, two evaluations of one 100-step episode) of
oops-td3 on Hopper, ``ilfo train`` with ``ILFO_COMPILATION_CACHE=off`` (a first run's
compilation): 33.7 s of CPU time, user and system (92 s wall beside two pinned runs), less
its 400 steps at the measured rate (1.3 s); 2026-12-07, the 2-core Intel Xeon
machine. Algos that compile more programs (opolo, firl-fkl) likely cost more, a start that
finds its programs in the compilation cache less."""


MEASURE_SECONDS_PER_PAIR: dict[str, float] = {"distances": 0.6, "solvers": 45.0}
"""For the estimate only: one core's seconds per (final rollout, expert trajectory) pair of
each measure, on Hopper and Walker2d (2026-12-06, beside one or two training runs): Table 3's
three exact solves, with the rollouts, 0.5-1.2 s a pair (0.6 on average over the small
budget's six runs of 100 pairs, 47-120 s a run); the solver figure's nine solves (three
Sinkhorn ones to their 20,000-iteration cap) about 50 s a pair (docs/experiments.md)."""


def run_core_seconds(
    config: Mapping[str, Any], steps: int, *, unmeasured_rate: float | None = None
) -> float | None:
    """One core's estimated seconds for ``steps`` steps of a run with ``config``'s algo,
    preset and updates per step (a sweep's settings, ``ilfo train``'s defaults where absent):
    its fixed cost (``RUN_FIXED_CORE_SECONDS``) and its steps at ``steps_per_core_second``
    (its env's rate where measured),
    a third of it at the paper preset where that changes the agent, times ``UPDATE_SHARE``'s
    cost of more updates per step. 0 for no steps; None for an algo without a measured rate,
    unless ``unmeasured_rate`` (steps/s at the fast preset) stands in for one."""
    algo = config["algo"]
    rate = steps_per_core_second(algo, config.get("env"))
    rate = unmeasured_rate if rate is None else rate
    if steps <= 0:
        return 0.0
    if rate is None:
        return None
    if config.get("preset", "paper") == "paper" and preset_changes_agent_of(algo):
        rate /= 3
    return RUN_FIXED_CORE_SECONDS + steps / rate * _updates_cost(config)


def _updates_cost(config: Mapping[str, Any]) -> float:
    """How many times a step at one update per step a run's step costs (``UPDATE_SHARE``)."""
    updates = config.get("updates_per_step", 1)
    if updates == 1 or is_on_policy(config["algo"]):
        return 1.0
    share = UPDATE_SHARE[config.get("preset", "paper")]
    return (1 - share) + share * updates


@functools.cache
def preset_changes_agent_of(algo: str) -> bool:
    """Whether ``--preset`` changes the algo's agent (TD3 and DDPG's critics; not SAC, OPOLO or
    the baselines' authors' settings), so that the paper preset runs slower than the rates."""
    return algo in ALGOS and preset_changes_agent(TrainConfig(algo=algo))


def is_on_policy(algo: str) -> bool:
    """Whether ``algo`` learns from batches of its own episodes (``updates_per_step`` does not
    apply to it)."""
    return algo in ALGOS and ALGOS[algo].learner == "on_policy"
