"""SIL-(s,s'): Sinkhorn Imitation Learning's reward on state transitions (Papagiannis & Li), as
the OOPS paper's baseline runs it with the learner's next state in place of its action.

As in the SIL authors' code (docs/notes/sil-spec.md, sections 2 to 5): each learner episode's
atoms (s_t, s_t+1) are matched to one expert trajectory drawn at random, subsampled to every 20th
step (50 atoms from 1,000 steps), with the cosine distance between the features of an
adversarial critic (``ilfo.rewards.adversarial``) as the ground cost and an entropic coupling P
(lambda = 0.01). Step t's reward is

    r_t = -2 c_t + 4 / T,   c_t = sum_j P_tj C_tj,   T the episode's transitions,

in [0, 4 / T] (the code's "survival bonus" 4 / T), divided by a running standard deviation of
every reward so far (no mean subtracted) and clipped to +-10: the code's reward filter. Once per
batch of the on-policy learner (TRPO), ``end_batch`` takes one Adam step of the critic maximising
the batch's transported costs with the plans held fixed, then forgets the batch.

Where ilfo departs (docs/notes/sil-spec.md, section 6.6 and 9):

- observations are normalised by a fixed z-score fitted on the demos' states (mean; std with
  ddof=1, floored at 0.33), clipped to +-``obs_clip``, on both sides. The authors used the
  running normaliser of their TRPO expert's training run, which ilfo's SAC experts do not have;
- the expert subsampling draws its phase in [0, ``expert_subsample``) for every learner episode
  (the authors' script fixed one phase per stored trajectory, when it made the data set); s' of a
  kept step is the true next observation of that step, as the OOPS paper's (s, s') reading says;
- the cosine cost has a 1e-12 floor on the feature norms (``adversarial.COSINE_EPS``);
- the Sinkhorn solve is ilfo's (float64, stabilised, ``tol`` on both marginals' L1 error)
  instead of POT's (a squared-L2 criterion on the expert marginal only).
"""

from __future__ import annotations

import math
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

__all__ = ["SIL", "RunningStd", "SILConfig"]

_STD_FLOOR = 0.33
"""Floor of the observation normaliser's std: ilfo's network normaliser's
(``training.build.network_normalizer``)."""

_FILTER_EPS = 1e-8
"""Added to the running std before dividing (the authors' reward filter's)."""


@dataclass(frozen=True)
class SILConfig:
    """SIL-(s,s')'s reward and its critic. Defaults: the SIL authors' code and README command."""

    critic_hidden: tuple[int, ...] = widths((128, 128))
    """Hidden layer widths (ReLU) of the adversarial critic."""
    critic_features: int = width(30)
    """Output features of the critic (a linear layer): the space of the cosine cost."""
    critic_lr: float = learning_rate(5e-4)
    """Adam learning rate of the critic (one step per batch, in ``end_batch``)."""
    reg: float = positive(0.01)
    """Sinkhorn's absolute entropic regularisation lambda (the cosine cost lies in [0, 2])."""
    tol: float = positive(1e-9)
    """Sinkhorn stops when the L1 error of both marginals is below this."""
    max_iter: int = count(100_000, check=check_count)
    """Most Sinkhorn iterations (the authors' cap, 1e9, means "to convergence"; at lambda 0.01
    a 1000 x 50 problem takes from a few to ~1,500 iterations)."""
    expert_subsample: int = count(20)
    """Expert atoms are every this many steps of the drawn demo, from a random phase in
    [0, expert_subsample) drawn per learner episode (the authors' data: 50 atoms from 1,000
    steps); 1 keeps every step."""
    reward_clip: float = positive(10.0, inf=True, note="inf: no clipping")
    """Rewards divided by their running std are clipped to [-reward_clip, reward_clip]."""
    obs_clip: float = positive(5.0, inf=True, note="inf: no clipping")
    """Normalised observations are clipped to [-obs_clip, obs_clip]."""
    seed: int = rng_seed()
    """Seed of the critic's initialisation and of the generator of the expert draws (demo and
    phase)."""

    def __post_init__(self) -> None:
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)


class RunningStd:
    """The authors' reward filter: x / (running std + 1e-8), clipped; no mean subtracted.

    The statistics (Welford's) are updated with each value before it is divided, one value at a
    time. The variance is the sample variance (ddof=1) after two values or more, and the first
    value's square after one, so that the first value ever becomes +-1.
    """

    def __init__(self, clip: float) -> None:
        self.clip = clip
        self.count = 0
        self.mean = 0.0
        self.m2 = 0.0

    def __call__(self, values: np.ndarray) -> np.ndarray:
        """Update with each of ``values`` in order and return each divided and clipped."""
        out = np.empty(len(values))
        # Sequential on purpose: each value's divisor includes itself and those before it.
        for i, x in enumerate(np.asarray(values, dtype=np.float64).tolist()):
            self.count += 1
            if self.count == 1:
                self.mean, self.m2 = x, 0.0
                var = x * x
            else:
                delta = x - self.mean
                self.mean += delta / self.count
                self.m2 += delta * (x - self.mean)
                var = self.m2 / (self.count - 1)
            out[i] = x / (math.sqrt(var) + _FILTER_EPS)
        return np.clip(out, -self.clip, self.clip)

    def state(self) -> dict[str, Any]:
        """The statistics, JSON-serialisable (floats round-trip exactly)."""
        return {"count": self.count, "mean": self.mean, "m2": self.m2}

    def load_state(self, state: dict[str, Any]) -> None:
        """Continue from what ``state`` returned."""
        self.count = int(state["count"])
        self.mean, self.m2 = float(state["mean"]), float(state["m2"])


@dataclass(frozen=True)
class _Pending:
    """An episode rewarded since the critic's last step: what the step needs."""

    atoms: np.ndarray
    demo: int
    phase: int
    plan: np.ndarray
    distance: float
    reward_sum: float


class SIL:
    """The SIL-(s,s') rewarder: ``SIL(demos, config)(observations) -> RewardOutput``, and
    ``end_batch()`` after each batch of the on-policy learner.

    Args:
        demos: Expert demonstrations, each observations of shape (T_i + 1, obs_dim).
        config: A ``SILConfig``; the authors' defaults if None.
    """

    def __init__(self, demos: Sequence[np.ndarray], config: SILConfig | None = None) -> None:
        self.config = cfg = config or SILConfig()
        demos = check_demos(demos)
        self.obs_dim = demos[0].shape[1]
        # mean, and scale = max(std, 0.33) (a zero std becomes 1): the Standardizer's fit with
        # the z-score's factor and no eps.
        self.normalizer = Standardizer.from_demos(
            demos, std_factor=1.0, std_floor=_STD_FLOOR, eps=0
        )
        self.expert_atoms = [make_atoms(self.normalize(d), "transitions") for d in demos]
        self.critic = AdversarialCritic(cfg.critic_hidden, cfg.critic_features, cfg.critic_lr)
        self.critic_state = self.critic.init(jax.random.PRNGKey(cfg.seed), 2 * self.obs_dim)
        self.rng = np.random.default_rng(cfg.seed)
        self.reward_filter = RunningStd(cfg.reward_clip)
        self._pending: list[_Pending] = []

    def normalize(self, observations: np.ndarray) -> np.ndarray:
        """The fixed z-score of the demos' states, clipped to +-obs_clip: (..., obs_dim)."""
        clip = self.config.obs_clip
        return np.clip(self.normalizer(observations), -clip, clip)

    def expert_draw(self, demo: int, phase: int) -> np.ndarray:
        """The expert atoms of demo ``demo`` kept from step ``phase`` on, every
        ``expert_subsample`` steps: (s_t, s_t+1) with s_t+1 the demo's next observation."""
        return self.expert_atoms[demo][phase :: self.config.expert_subsample]

    def __call__(self, observations: np.ndarray) -> RewardOutput:
        """Filtered rewards (T,) of one learner episode's observations (T + 1, obs_dim), with the
        critic as it is (its step comes at ``end_batch``)."""
        observations = check_episode(observations, self.obs_dim)
        atoms = make_atoms(self.normalize(observations), "transitions")
        demo = int(self.rng.integers(len(self.expert_atoms)))
        # A demo shorter than the stride has fewer phases (each keeps at least one atom).
        phase = int(
            self.rng.integers(min(self.config.expert_subsample, len(self.expert_atoms[demo])))
        )
        coupling = self._solve(atoms, demo, phase)
        num_steps = len(atoms)
        raw = -2.0 * coupling.row_costs + 4.0 / num_steps
        rewards = self.reward_filter(raw)
        self._pending.append(
            _Pending(atoms, demo, phase, coupling.plan, coupling.cost, float(rewards.sum()))
        )
        return RewardOutput(
            rewards=rewards, coupling=coupling, distance=coupling.cost, demo_index=demo
        )

    def end_batch(self) -> dict[str, float]:
        """One critic step on every episode rewarded since the last call, then forget them.

        Returns:
            ``reward_loss`` (the critic's loss before the step: minus the summed transport costs
            over N - 1), ``reward_mean`` (the mean filtered reward of the batch's steps: what the
            learner was given) and ``reward_distance`` (the mean transport cost <P, C> of its
            episodes); {} and nothing done if no episode is pending.
        """
        if not self._pending:
            return {}
        pending, self._pending = self._pending, []
        pairs = [(p.atoms, self.expert_draw(p.demo, p.phase), p.plan) for p in pending]
        self.critic_state, loss = self.critic.step(self.critic_state, pairs)
        steps = sum(len(p.atoms) for p in pending)
        return {
            "reward_loss": loss,
            "reward_mean": sum(p.reward_sum for p in pending) / steps,
            "reward_distance": float(np.mean([p.distance for p in pending])),
        }

    @property
    def pending_episodes(self) -> int:
        """Episodes rewarded since the last ``end_batch``."""
        return len(self._pending)

    def state(self) -> RewardState:
        """Everything a resumed run needs to reward and learn exactly as the uninterrupted one.

        values: ``rng`` (the expert draws' generator), ``filter`` (the reward filter's count,
        mean and m2), ``pending`` (per pending episode: ``demo``, ``phase``, ``reward_sum``).
        arrays: the critic's parameters and Adam state (``critic/...``) and each pending
        episode's learner atoms (``pending/<k>``). The pending plans are not stored: the critic
        has not moved since they were solved, so ``load_state`` solves them again, identically.
        """
        values = {
            "rng": self.rng.bit_generator.state,
            "filter": self.reward_filter.state(),
            "pending": [
                {"demo": p.demo, "phase": p.phase, "reward_sum": p.reward_sum}
                for p in self._pending
            ],
        }
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
                self._restore_pending(k, entry, arrays, critic_state.params)
                for k, entry in enumerate(values["pending"])
            ]
        # Nothing changes until everything has been read.
        self.critic_state, self._pending = critic_state, pending
        if "rng" in values:
            self.rng.bit_generator.state = values["rng"]
        if "filter" in values:
            self.reward_filter.load_state(values["filter"])

    def _restore_pending(
        self, k: int, entry: dict[str, Any], arrays: dict[str, np.ndarray], params: Any
    ) -> _Pending:
        demo, phase = int(entry["demo"]), int(entry["phase"])
        atoms = pending_atoms(arrays, k, 2 * self.obs_dim)
        if not 0 <= demo < len(self.expert_atoms) or not 0 <= phase < len(self.expert_atoms[demo]):
            raise ValueError(f"pending episode {k}: demo {demo}, phase {phase} fit no demo here")
        coupling = self._solve(atoms, demo, phase, params)
        return _Pending(
            atoms, demo, phase, coupling.plan, coupling.cost, float(entry["reward_sum"])
        )

    def _solve(self, atoms: np.ndarray, demo: int, phase: int, params: Any = None) -> OTResult:
        cfg = self.config
        params = self.critic_state.params if params is None else params
        cost = self.critic.cost(params, atoms, self.expert_draw(demo, phase))
        return sinkhorn(cost, reg=cfg.reg, tol=cfg.tol, max_iter=cfg.max_iter)
