"""PWIL: Primal Wasserstein Imitation Learning (Dadashi et al., ICLR 2021), state-only PWIL-(s).

Each learner step, in order, takes mass 1/horizon from the nearest expert atoms that still have
mass (the greedy coupling, as PWIL computes it online along the episode); its reward is
alpha * exp(-beta * horizon / sqrt(d) * c_t), c_t the cost it transported, on states standardised
by the expert std. Atoms are the state each transition leads to, s_t+1.

Two settings of PWIL's own code are options here, off by default (the defaults are what ilfo's
PWIL-(s) results were run with): it keeps every 20th state of each demo from a random offset
(``subsample``), and its d is |S| + |A| even when it imitates from states alone
(``kernel_dim``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ilfo.ot import cost_matrix, greedy
from ilfo.ranges import check_fields, count, positive, rng_seed
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

    alpha: float = positive(5.0)
    """Reward amplitude alpha."""
    beta: float = positive(5.0)
    """Kernel width beta."""
    horizon: int | None = count(None)
    """Learner mass per step is 1 / horizon (PWIL uses the episode limit, 1,000 in MuJoCo);
    None uses the episode's own length."""
    subsample: int = count(1)
    """Keep every ``subsample``-th state of each demo, from a random offset in [0, subsample)
    drawn per demo (PWIL's code: 20 on MuJoCo, so a 1,000-step demo gives 50 atoms of weight
    1/50); 1 keeps every state."""
    kernel_dim: int | None = count(None)
    """The d in the kernel's sqrt(d); None: the observations' dimension |S|. PWIL's code uses
    |S| + |A| also in its observation-only mode (23 on Walker2d, 14 on Hopper)."""
    seed: int = rng_seed()
    """Draws the subsampling offsets. Set by the trainer: the run's seed."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


class PWIL:
    """The PWIL-(s) rewarder: ``PWIL(demos, config)(observations) -> RewardOutput``.

    All demos are pooled, with uniform weights, as in PWIL.
    """

    def __init__(self, demos: Sequence[np.ndarray], config: PWILConfig | None = None) -> None:
        if config is not None and not isinstance(config, PWILConfig):
            raise TypeError(f"config must be a PWILConfig, got {type(config).__name__}")
        self.config = config or PWILConfig()
        demos = check_demos(demos)
        self.obs_dim = demos[0].shape[1]
        # Euclidean distances ignore the mean, so only the expert std matters (PWIL's scaler).
        self.standardizer = Standardizer.from_demos(demos, std_factor=1.0, std_floor=0.0, eps=0.0)
        step, rng = self.config.subsample, np.random.default_rng(self.config.seed)
        # The offset stays within a short demo, so that each demo keeps at least one atom.
        self.expert_atoms = np.concatenate(
            [
                self.standardizer(d[1:][rng.integers(0, min(step, len(d) - 1)) :: step])
                for d in demos
            ]
        )

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
        scale = cfg.beta * horizon / np.sqrt(cfg.kernel_dim or self.obs_dim)
        return RewardOutput(
            rewards=cfg.alpha * np.exp(-scale * coupling.row_costs),
            coupling=coupling,
            distance=coupling.cost,
            demo_index=None,
        )
