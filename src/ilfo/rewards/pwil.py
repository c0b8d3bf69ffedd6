"""PWIL: Primal Wasserstein Imitation Learning (Dadashi et al., ICLR 2021), state-only PWIL-(s).

Each learner step, in order, takes mass 1/horizon from the nearest expert atoms that still have
mass (the greedy coupling, as PWIL computes it online along the episode); its reward is
alpha * exp(-beta * horizon / sqrt(d) * c_t), c_t the cost it transported, on states standardised
by the expert std. Atoms are the state each transition leads to, s_t+1.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ilfo.ot import cost_matrix, greedy
from ilfo.rewards.base import (
    RewardOutput,
    RewardState,
    Standardizer,
    check_demos,
    check_episode,
)


@dataclass(frozen=True)
class PWILConfig:
    """PWIL-(s) as the paper ran it."""

    alpha: float = 5.0
    """Reward amplitude alpha."""
    beta: float = 5.0
    """Kernel width beta."""
    horizon: int | None = None
    """Learner mass per step is 1 / horizon (PWIL uses the episode limit, 1,000 in MuJoCo);
    None uses the episode's own length."""

    def __post_init__(self) -> None:
        if self.horizon is not None and self.horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {self.horizon!r}")


class PWIL:
    """The PWIL-(s) rewarder: ``PWIL(demos, config)(observations) -> RewardOutput``.

    All demos are pooled, with uniform weights, as in PWIL.
    """

    def __init__(self, demos: Sequence[np.ndarray], config: PWILConfig | None = None) -> None:
        self.config = config or PWILConfig()
        demos = check_demos(demos)
        self.obs_dim = demos[0].shape[1]
        # Euclidean distances ignore the mean, so only the expert std matters (PWIL's scaler).
        self.standardizer = Standardizer.from_demos(demos, std_factor=1.0, std_floor=0.0, eps=0.0)
        self.expert_atoms = np.concatenate([self.standardizer(d[1:]) for d in demos])

    def state(self) -> RewardState:
        """Nothing: PWIL-(s) rewards each episode on its own (its coupling is deterministic)."""
        return RewardState()

    def load_state(self, state: RewardState) -> None:
        """Nothing to restore (see ``state``)."""

    def __call__(self, observations: np.ndarray) -> RewardOutput:
        """Rewards (T,) of one learner episode's observations (T + 1, obs_dim)."""
        observations = check_episode(observations, self.obs_dim)
        learner = self.standardizer(observations[1:])
        num_steps = len(learner)
        horizon = self.config.horizon or num_steps
        if horizon < num_steps:
            raise ValueError(f"episode has {num_steps} steps, more than horizon {horizon}")
        a = np.full(num_steps, 1.0 / horizon)
        coupling = greedy(cost_matrix(learner, self.expert_atoms, "euclidean"), a=a)
        cfg = self.config
        scale = cfg.beta * horizon / np.sqrt(self.obs_dim)
        return RewardOutput(
            rewards=cfg.alpha * np.exp(-scale * coupling.row_costs),
            coupling=coupling,
            distance=coupling.cost,
            demo_index=None,
        )
