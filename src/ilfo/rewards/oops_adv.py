"""OOPS_adv: OOPS whose ground cost is SIL's learned adversarial distance (the OOPS paper's
"Adversarial Distance" ablation, Table 4).

Everything is OOPS's (``ilfo.rewards.oops``) except the cost: OOPS's standardised (s, s') atoms
of the whole learner episode and of one whole demo drawn at random, an entropic coupling P
(lambda 0.05), and r_t = -reward_scale * T / sqrt(obs_dim) * sum_j P_tj C_tj; but C is the cosine
distance between the features of SIL's adversarial critic (``ilfo.rewards.adversarial``), which
learns to make the learner's transported cost large. No survival bonus and no reward filter:
those belong to SIL's TRPO pipeline.

The paper gives one sentence (docs/notes/sil-spec.md, section 8): nothing of when, how often or
on what the critic learns. ilfo's choice, the closest to SIL: each episode is rewarded with the
critic as it is, then, once ``critic_every`` episodes have been rewarded since the critic's last
step, the critic takes one Adam step on those episodes (their plans held fixed, as in SIL).
Rewards already in the replay buffer are not recomputed, so they go stale as the critic moves:
OOPS's argument for stale rewards assumes a fixed cost, and does not cover this.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import jax
import numpy as np

from ilfo.ot import OTResult, sinkhorn
from ilfo.ot._checks import check_count
from ilfo.ranges import check_fields, count, learning_rate, positive, rng_seed, width, widths
from ilfo.rewards.adversarial import (
    AdversarialCritic,
    critic_arrays,
    load_critic_arrays,
    pending_atoms,
)
from ilfo.rewards.base import (
    RewardOutput,
    RewardState,
    Standardizer,
    check_demos,
    check_episode,
    make_atoms,
)

__all__ = ["AdversarialOOPS", "AdversarialOOPSConfig"]


@dataclass(frozen=True)
class AdversarialOOPSConfig:
    """OOPS with SIL's adversarial cosine cost. The paper gives none of the critic's settings or
    schedule: the critic is SIL's, and its schedule (one step every ``critic_every`` episodes)
    is ilfo's choice (docs/notes/sil-spec.md, section 8)."""

    critic_hidden: tuple[int, ...] = widths((128, 128))
    """Hidden layer widths (ReLU) of the critic (SIL's)."""
    critic_features: int = width(30)
    """Output features of the critic (SIL's): the space of the cosine cost."""
    critic_lr: float = learning_rate(5e-4)
    """Adam learning rate of the critic (SIL's; the paper gives none for OOPS_adv)."""
    reg: float = positive(0.05)
    """Sinkhorn's absolute entropic regularisation lambda: OOPS's (the paper's appendix); SIL's
    0.01 is the alternative (the paper does not say which OOPS_adv used)."""
    tol: float = positive(1e-9)
    """Sinkhorn stops when the L1 error of both marginals is below this."""
    max_iter: int = count(20000, check=check_count)
    """Most Sinkhorn iterations (OOPS's)."""
    reward_scale: float = positive(5.0)
    """r_t = -reward_scale * T / sqrt(obs_dim) * sum_j C_tj P_tj, as OOPS."""
    critic_every: int = count(1)
    """The critic takes one Adam step on the last ``critic_every`` episodes each time that many
    have been rewarded since its last step (the paper gives no schedule; 1: a step per episode,
    on that episode alone, after its rewards; SIL's is one step per ~50 episodes)."""
    seed: int = rng_seed()
    """Seed of the critic's initialisation and of the generator that draws a demo per episode."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


@dataclass(frozen=True)
class _Pending:
    """An episode rewarded since the critic's last step."""

    atoms: np.ndarray
    demo: int
    plan: np.ndarray


class AdversarialOOPS:
    """The OOPS_adv rewarder: ``AdversarialOOPS(demos, config)(observations) -> RewardOutput``.

    Args:
        demos: Expert demonstrations, each observations of shape (T_i + 1, obs_dim).
        config: An ``AdversarialOOPSConfig``; its defaults if None.
    """

    def __init__(
        self, demos: Sequence[np.ndarray], config: AdversarialOOPSConfig | None = None
    ) -> None:
        self.config = cfg = config or AdversarialOOPSConfig()
        demos = check_demos(demos)
        self.obs_dim = demos[0].shape[1]
        self.standardizer = Standardizer.from_demos(demos)
        self.expert_atoms = [make_atoms(self.standardizer(d), "transitions") for d in demos]
        self.critic = AdversarialCritic(cfg.critic_hidden, cfg.critic_features, cfg.critic_lr)
        self.critic_state = self.critic.init(jax.random.PRNGKey(cfg.seed), 2 * self.obs_dim)
        self.rng = np.random.default_rng(cfg.seed)
        self._pending: list[_Pending] = []

    def __call__(self, observations: np.ndarray) -> RewardOutput:
        """Rewards (T,) of one learner episode's observations (T + 1, obs_dim), with the critic as
        it was before this episode; then the critic's step, if one falls due."""
        observations = check_episode(observations, self.obs_dim)
        atoms = make_atoms(self.standardizer(observations), "transitions")
        demo = int(self.rng.integers(len(self.expert_atoms)))
        coupling = self._solve(atoms, demo)
        scale = self.config.reward_scale * len(atoms) / np.sqrt(self.obs_dim)
        output = RewardOutput(
            rewards=-scale * coupling.row_costs,
            coupling=coupling,
            distance=coupling.cost,
            demo_index=demo,
        )
        self._pending.append(_Pending(atoms, demo, coupling.plan))
        if len(self._pending) >= self.config.critic_every:
            pairs = [(p.atoms, self.expert_atoms[p.demo], p.plan) for p in self._pending]
            self.critic_state, _ = self.critic.step(self.critic_state, pairs)
            self._pending = []
        return output

    def state(self) -> RewardState:
        """Everything a resumed run needs to reward exactly as the uninterrupted one.

        values: ``rng`` (the demo draws' generator), ``pending`` (the demo of each episode
        rewarded since the critic's last step). arrays: the critic's parameters and Adam state
        (``critic/...``) and each pending episode's atoms (``pending/<k>``). Pending plans are
        solved again on load: the critic has not moved since they were solved.
        """
        values = {"rng": self.rng.bit_generator.state, "pending": [p.demo for p in self._pending]}
        arrays = critic_arrays(self.critic_state, "critic/")
        arrays.update({f"pending/{k}": p.atoms for k, p in enumerate(self._pending)})
        return RewardState(values=values, arrays=arrays)

    def load_state(self, state: RewardState) -> None:
        """Continue from what ``state`` returned (a missing part is left as it is).

        Raises:
            ValueError: the critic's arrays do not fit this critic, or a pending episode does not
                fit these demos.
        """
        values, arrays = state.values, state.arrays
        critic_state = self.critic_state
        if any(name.startswith("critic/") for name in arrays):
            critic_state = load_critic_arrays(critic_state, arrays, "critic/")
        pending = self._pending
        if "pending" in values:  # solved with the loaded critic: the one that rewarded them
            pending = [
                self._restore_pending(k, demo, arrays, critic_state.params)
                for k, demo in enumerate(values["pending"])
            ]
        # Nothing changes until everything has been read.
        self.critic_state, self._pending = critic_state, pending
        if "rng" in values:
            self.rng.bit_generator.state = values["rng"]

    def _restore_pending(
        self, k: int, demo: Any, arrays: dict[str, np.ndarray], params: Any
    ) -> _Pending:
        demo = int(demo)
        atoms = pending_atoms(arrays, k, 2 * self.obs_dim)
        if not 0 <= demo < len(self.expert_atoms):
            raise ValueError(f"pending episode {k}: demo {demo} out of {len(self.expert_atoms)}")
        return _Pending(atoms, demo, self._solve(atoms, demo, params).plan)

    def _solve(self, atoms: np.ndarray, demo: int, params: Any = None) -> OTResult:
        cfg = self.config
        params = self.critic_state.params if params is None else params
        cost = self.critic.cost(params, atoms, self.expert_atoms[demo])
        return sinkhorn(cost, reg=cfg.reg, tol=cfg.tol, max_iter=cfg.max_iter)
