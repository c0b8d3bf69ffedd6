"""OOPS: Observational Off-Policy Sinkhorn rewards (Chang et al., RLC 2024).

Reward of learner step t: r_t = -scale * sum_j C_tj P_tj, with P the entropic OT coupling between
the learner's transitions (s_t, s_t+1) and an expert demonstration's, C the square root of the
Euclidean distance between standardised atoms, and scale = reward_scale * T / sqrt(obs_dim).
Defaults reproduce the paper's code (see docs/reproduction.md for where it departs from the text).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ilfo.ot import METRICS, Metric, OTResult, Solver, cost_matrix, solve
from ilfo.ot._checks import check_count
from ilfo.ranges import check_fields, count, positive, rng_seed
from ilfo.rewards.base import (
    Atoms,
    RewardOutput,
    RewardState,
    Standardizer,
    check_demos,
    check_episode,
    make_atoms,
)

DemoSelection = Literal["random", "pooled", "nearest"]
Kernel = Literal["linear", "exponential"]
KERNELS: tuple[str, ...] = ("linear", "exponential")


@dataclass(frozen=True)
class OOPSConfig:
    """How OOPS turns a learner episode into rewards. Defaults are the paper's."""

    atoms: Atoms = "transitions"
    """``transitions`` (s_t, s_t+1), the paper's default, or ``states`` (s_t+1 alone: the
    state-occupancy ablation)."""
    metric: Metric = "sqrt_euclidean"
    """Ground cost between atoms: ``sqrt_euclidean`` (W1 with d = sqrt(L2), the paper's),
    ``euclidean`` (W1/L2), ``sqeuclidean`` (W2/L2) or ``cosine``."""
    solver: Solver = "sinkhorn"
    """Coupling: ``sinkhorn`` (entropic OT), ``emd`` (exact network simplex) or ``greedy``
    (PWIL's greedy coupling)."""
    reg: float = positive(0.05)
    """Sinkhorn's absolute entropic regularisation lambda."""
    tol: float = positive(1e-9)
    """Sinkhorn stops when the L1 error of both marginals is below this times the mass (1:
    OOPS's weights are uniform)."""
    max_iter: int = count(20000, check=check_count)
    """Most Sinkhorn iterations (the paper's code always ran 20,000, in float32)."""
    reward_scale: float = positive(5.0)
    """r_t = -reward_scale * T / sqrt(obs_dim) * sum_j C_tj P_tj, T the learner's number of
    transitions (1,000 in the paper's fixed-horizon episodes); with the exponential kernel, the
    amplitude alpha."""
    kernel: Kernel = "linear"
    """How a step's transported cost becomes its reward: ``linear``, the paper's
    -reward_scale * T / sqrt(obs_dim) * sum_j C_tj P_tj, or ``exponential``,
    reward_scale * exp(-kernel_rate * T / sqrt(obs_dim) * sum_j C_tj P_tj), PWIL's and OTR's
    form, which pays mostly for steps close to some expert atom (not in the paper's runs)."""
    kernel_rate: float = positive(5.0)
    """beta of the exponential kernel (PWIL's and OTR's 5); unused by the linear one."""
    demo_selection: DemoSelection = "random"
    """With several demos: ``random`` (one drawn per episode, the paper's code), ``pooled``
    (all demos' atoms together, uniform weights) or ``nearest`` (the demo with the smallest OT
    distance to the episode; costs one solve per demo)."""
    standardize: bool = True
    """Standardise states as the paper's code: (s - mean) / (3 * max(std, 0.33) + 1e-8), with
    mean and std from the demos only."""
    warm_start: bool = False
    """Start each Sinkhorn solve from the potentials of the last solve against the same demo
    (same result to tol, fewer iterations when episodes change slowly; off by default so that a
    reward depends on its episode alone)."""
    time_index: bool = False
    """Append 2 * time-to-go / T to each (standardised) state before atoms are made, T the
    episode's (or demo's) number of transitions, so that OT matches steps at similar times
    (the OOPS authors' ``use_time_index``; off in the paper's runs)."""
    time_weighted_cost: bool = False
    """Multiply the cost of atom i of n (learner) and j of m (expert) by 1 + |i/n - j/m|,
    penalising matches far apart in time (the authors' ``use_tcot``; off in the paper's
    runs). With ``demo_selection='pooled'`` j/m is the position within the atom's own demo."""
    seed: int = rng_seed()
    """Seed of the generator that draws the demo with ``demo_selection='random'``."""

    def __post_init__(self) -> None:
        if self.metric not in METRICS:
            raise ValueError(f"unknown metric {self.metric!r}; choose one of {', '.join(METRICS)}")
        if self.kernel not in KERNELS:
            raise ValueError(f"unknown kernel {self.kernel!r}; choose one of {', '.join(KERNELS)}")
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


def _positions(count: int) -> np.ndarray:
    """Atom i's position i / count in its episode, for ``time_weighted_cost``."""
    return np.arange(count, dtype=np.float64) / count


class OOPS:
    """The OOPS rewarder: ``OOPS(demos, config)(observations) -> RewardOutput``.

    Args:
        demos: Expert demonstrations, each observations of shape (T_i + 1, obs_dim).
        config: An ``OOPSConfig``; the paper's defaults if None.
    """

    def __init__(self, demos: Sequence[np.ndarray], config: OOPSConfig | None = None) -> None:
        if config is not None and not isinstance(config, OOPSConfig):
            raise TypeError(f"config must be an OOPSConfig, got {type(config).__name__}")
        self.config = config or OOPSConfig()
        demos = check_demos(demos)
        self.obs_dim = demos[0].shape[1]
        if self.config.standardize:
            self.standardizer = Standardizer.from_demos(demos)
        else:
            dim = self.obs_dim
            self.standardizer = Standardizer(mean=np.zeros(dim), scale=np.ones(dim))
        self.expert_atoms = [self._atoms(d) for d in demos]
        self.expert_positions = [_positions(len(a)) for a in self.expert_atoms]
        self.rng = np.random.default_rng(self.config.seed)
        self._potentials: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def __call__(self, observations: np.ndarray) -> RewardOutput:
        """Rewards (T,) of one learner episode's observations (T + 1, obs_dim)."""
        observations = check_episode(observations, self.obs_dim)
        learner = self._atoms(observations)
        selection = self.config.demo_selection
        if selection == "pooled":
            index, coupling = None, self._solve(learner, -1)
        elif selection == "random":
            index = int(self.rng.integers(len(self.expert_atoms)))
            coupling = self._solve(learner, index)
        else:
            solved = [self._solve(learner, i) for i in range(len(self.expert_atoms))]
            index = int(np.argmin([s.cost for s in solved]))
            coupling = solved[index]
        # Each row's cost at mass 1 (not 1/T), per square root of the state's width.
        cost = len(learner) / np.sqrt(self.obs_dim) * coupling.row_costs
        if self.config.kernel == "linear":
            rewards = -self.config.reward_scale * cost
        else:
            rewards = self.config.reward_scale * np.exp(-self.config.kernel_rate * cost)
        return RewardOutput(
            rewards=rewards,
            coupling=coupling,
            distance=coupling.cost,
            demo_index=index,
        )

    def couplings(self, observations: np.ndarray) -> list[OTResult]:
        """The episode's coupling with each demo in turn (no draw, no pooling): what offline
        labelling aggregates over demos (``ilfo.labelling``). ``row_costs`` are the raw
        transported costs, before OOPS's reward scale."""
        observations = check_episode(observations, self.obs_dim)
        learner = self._atoms(observations)
        return [self._solve(learner, i) for i in range(len(self.expert_atoms))]

    def state(self) -> RewardState:
        """The demo draws' generator state, and the potentials kept for warm starts as named
        arrays ``f_<demo>`` and ``g_<demo>`` (demo -1: the pooled demos; none without
        ``warm_start``)."""
        arrays = {}
        for key, (f, g) in self._potentials.items():
            arrays[f"f_{key}"], arrays[f"g_{key}"] = f, g
        return RewardState(values={"rng": self.rng.bit_generator.state}, arrays=arrays)

    def load_state(self, state: RewardState) -> None:
        """Continue from what ``state`` returned (a missing part is left as it is)."""
        if "rng" in state.values:
            self.rng.bit_generator.state = state.values["rng"]
        arrays = state.arrays
        keys = sorted(int(name[2:]) for name in arrays if name.startswith("f_"))
        self._potentials = {
            k: (np.asarray(arrays[f"f_{k}"]), np.asarray(arrays[f"g_{k}"])) for k in keys
        }

    def atoms(self, observations: np.ndarray) -> np.ndarray:
        """One episode's atoms (T, width) as OOPS compares them: its standardised states (with
        the time index where configured) made into transitions or states; ``cost`` takes them."""
        return self._atoms(check_episode(observations, self.obs_dim))

    def cost(self, learner: np.ndarray, demo: int) -> np.ndarray:
        """The ground cost (n, m) OOPS transports between an episode's atoms (``atoms``) and
        demo ``demo``'s (-1: all demos' atoms pooled): the metric, times 1 + |i/n - j/m| with
        ``time_weighted_cost``."""
        cfg = self.config
        expert = np.concatenate(self.expert_atoms) if demo == -1 else self.expert_atoms[demo]
        cost = cost_matrix(learner, expert, cfg.metric)
        if cfg.time_weighted_cost:
            # demo -1: the pooled demos, each atom at its position within its own demo.
            expert_positions = (
                np.concatenate(self.expert_positions) if demo == -1 else self.expert_positions[demo]
            )
            gap = np.abs(_positions(len(learner))[:, None] - expert_positions[None, :])
            cost = cost * (1.0 + gap).astype(cost.dtype)
        return cost

    def _atoms(self, observations: np.ndarray) -> np.ndarray:
        """An episode's atoms: its standardised states, with the time index where configured."""
        states = self.standardizer(observations)
        if self.config.time_index:
            steps = len(states) - 1
            time_to_go = 2.0 * np.arange(steps, -1, -1, dtype=np.float64) / max(steps, 1)
            states = np.concatenate([states, time_to_go[:, None].astype(states.dtype)], axis=1)
        return make_atoms(states, self.config.atoms)

    def _solve(self, learner: np.ndarray, key: int) -> OTResult:
        cfg = self.config
        cost = self.cost(learner, key)
        init = self._potentials.get(key) if cfg.warm_start else None
        if init is not None and (init[0].shape[0], init[1].shape[0]) != cost.shape:
            # A learner episode of another length, or a state saved against other demos.
            init = None
        result = solve(cost, cfg.solver, reg=cfg.reg, tol=cfg.tol, max_iter=cfg.max_iter, init=init)
        if cfg.warm_start and cfg.solver == "sinkhorn" and result.converged:
            assert result.f is not None and result.g is not None  # Sinkhorn's potentials
            self._potentials[key] = (result.f, result.g)
        return result
