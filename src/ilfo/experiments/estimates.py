"""What runs cost on one core: the measured rates that ``ilfo reproduce``'s plans and
``ilfo train``'s start summary estimate compute from (``run_core_seconds``, the one estimate
of a run), each with where and when it was measured."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

from ilfo.algos import ALGOS
from ilfo.training.config import TrainConfig, preset_changes_agent

STEPS_PER_CORE_SECOND: dict[str, float] = {
    "oops-td3": 300.0,
    "oops-ddpg": 300.0,
    "oops-sac": 120.0,
    "pwil-td3": 300.0,
    "gaifo-td3": 92.0,
    "opolo": 70.0,
    "firl-fkl": 77.0,
    "oops-adv-td3": 140.0,
    "sil": 300.0,
}
"""For the estimate only, steps per second of one core at the fast preset. oops-td3, oops-ddpg
and pwil-td3: the 8-task sweep's 1M-step Walker2d runs, each pinned to one core beside another
run, evaluations included (52 and 50 min: 320 and 332 steps/s, 2026-12-04; the wall times in
docs/results/runs/Walker2d-v5__oops-td3__0 and in the PWIL-(s) run on the fixed horizon,
docs/results/probes/Walker2d-v5__pwil-td3__0__fixed-horizon); the others half the 2-core loop
rates of ``bench/train.py`` (docs/notes/benchmarks-history.md, 2026-12-01; Hopper), and
oops-adv-td3 and sil from short probes on Hopper (2026-12-02), so likely on the low side. The
paper preset runs at about a third of the fast one."""


UPDATE_SHARE: dict[str, float] = {"fast": 0.7, "paper": 0.96}
"""For the estimate only: the share of an off-policy step's time spent in its update at one
update per step, by preset (``bench/train.py``, docs/notes/benchmarks-history.md: at the fast
preset the loop ran 1070, 624 and 361 steps/s at one, two and four updates per step; at the
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
its 400 steps at ``STEPS_PER_CORE_SECOND`` (1.3 s); 2026-12-07, the 2-core Intel Xeon
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
    its fixed cost (``RUN_FIXED_CORE_SECONDS``) and its steps at ``STEPS_PER_CORE_SECOND``,
    a third of it at the paper preset where that changes the agent, times ``UPDATE_SHARE``'s
    cost of more updates per step. 0 for no steps; None for an algo without a measured rate,
    unless ``unmeasured_rate`` (steps/s at the fast preset) stands in for one."""
    algo = config["algo"]
    rate = STEPS_PER_CORE_SECOND.get(algo, unmeasured_rate)
    if steps <= 0:
        return 0.0
    if rate is None:
        return None
    if config.get("preset", "paper") == "paper" and _preset_changes_agent(algo):
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
def _preset_changes_agent(algo: str) -> bool:
    """Whether ``--preset`` changes the algo's agent (TD3 and DDPG's critics; not SAC, OPOLO or
    the baselines' authors' settings), so that the paper preset runs slower than the rates."""
    return algo in ALGOS and preset_changes_agent(TrainConfig(algo=algo))


def is_on_policy(algo: str) -> bool:
    """Whether ``algo`` learns from batches of its own episodes (``updates_per_step`` does not
    apply to it)."""
    return algo in ALGOS and ALGOS[algo].learner == "on_policy"
