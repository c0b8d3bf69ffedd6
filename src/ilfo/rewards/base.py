"""What every episode reward shares: the protocol, input checks, the standardiser, atoms, and the
output type.

An episode reward (``EpisodeReward``) is built from expert demonstrations (each an array of
T_i + 1 observations) and maps one learner episode's observations (T + 1, obs_dim) to per-step
rewards (T,). It never sees actions or the task reward, and it knows nothing of the agent: the
training loop is where they meet.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from ilfo.demos.npz import DemoFile, Episode
from ilfo.ot import OTResult

Atoms = Literal["transitions", "states"]


@dataclass(frozen=True)
class RewardOutput:
    """Rewards of one learner episode, with what produced them (for diagnostics).

    Attributes:
        rewards: Per-step rewards, shape (T,): reward t belongs to the transition (s_t, s_t+1).
        coupling: The OT solution between learner atoms (T rows) and the expert atoms used.
        distance: The transport cost <C, P> of that coupling, in the rewarder's standardised
            space (the OT distance between learner and expert).
        demo_index: Which demonstration the learner was matched to; None when all were pooled.
    """

    rewards: np.ndarray
    coupling: OTResult
    distance: float
    demo_index: int | None


@dataclass(frozen=True)
class RewardState:
    """What an episode reward carries from one episode to the next, for checkpoints.

    Attributes:
        values: JSON-serialisable values (e.g. a numpy generator's ``bit_generator.state``).
        arrays: Named numpy arrays (e.g. Sinkhorn warm-start potentials).
    """

    values: dict[str, Any] = field(default_factory=dict)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)


class EpisodeReward(Protocol):
    """Rewards for one whole learner episode at a time (OOPS, PWIL): observations (T + 1,
    obs_dim) to a ``RewardOutput`` of T rewards. ``state`` and ``load_state`` carry what
    changes between episodes (random draws, warm starts) across a checkpoint, so that a resumed
    run rewards exactly as the uninterrupted one."""

    obs_dim: int

    def __call__(self, observations: np.ndarray) -> RewardOutput: ...

    def state(self) -> RewardState: ...

    def load_state(self, state: RewardState) -> None: ...


class BatchLearningReward(EpisodeReward, Protocol):
    """An episode reward that learns once per batch of an on-policy agent (SIL's adversarial
    critic): it rewards each episode as it ends, with its parameters of the time, and the loop
    calls ``end_batch`` when the agent has learned from the batch those episodes make."""

    def end_batch(self) -> dict[str, float]:
        """Learn from the episodes rewarded since the last call and forget them; returns
        metrics (``reward_loss``, ...), none where no episode was pending."""
        ...


@dataclass(frozen=True)
class Standardizer:
    """Per-dimension affine map s -> (s - mean) / scale, fitted on expert states only.

    Attributes:
        mean: Shape (obs_dim,).
        scale: Shape (obs_dim,), positive.
    """

    mean: np.ndarray
    scale: np.ndarray

    @classmethod
    def from_demos(
        cls,
        demos: Sequence[np.ndarray],
        std_factor: float = 3.0,
        std_floor: float = 0.33,
        eps: float = 1e-8,
    ) -> Standardizer:
        """Fit as the paper's code does: scale = std_factor * max(std, std_floor) + eps.

        mean and std (ddof=1) come from the demonstrations with each demo's last state left out;
        a zero std (below 1e-8: a constant column whose mean rounded, as the agents' normaliser
        tests it) becomes 1 before the floor. PWIL uses std_factor=1, std_floor=0, eps=0.
        """
        states = np.concatenate([d[:-1] for d in demos], axis=0)
        mean = states.mean(axis=0)
        std = states.std(axis=0, ddof=1) if len(states) > 1 else np.ones(states.shape[1])
        std = np.where(np.isclose(std, 0.0), 1.0, std)
        std = np.maximum(std, std_floor)
        return cls(mean=mean, scale=std_factor * std + eps)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Standardise observations of shape (..., obs_dim)."""
        return (observations - self.mean) / self.scale


def make_atoms(states: np.ndarray, atoms: Atoms) -> np.ndarray:
    """Atoms of an episode's (standardised) states (T + 1, d).

    ``transitions``: (s_t, s_t+1), shape (T, 2d). ``states``: s_t+1, the state each transition
    leads to, shape (T, d), so that reward t still depends on the action taken at t.
    """
    if atoms == "transitions":
        return np.concatenate([states[:-1], states[1:]], axis=1)
    if atoms == "states":
        return states[1:]
    raise ValueError(f"atoms must be 'transitions' or 'states', got {atoms!r}")


LOAD_DEMOS = (
    "load a demonstration file with ilfo.demos.load(path) (ilfo.demos.load_any for Minari, D4RL "
    "and imitation files) and pass [e.observations for e in demo_file.episodes]"
)
"""How to turn a file into what a reward takes, for the errors of ``check_demo_types``."""


def check_demo_types(demos: object) -> None:
    """Raise a TypeError saying what to pass where ``demos`` holds demonstrations rather than
    being them: a file name, a ``DemoFile`` or ``Episode`` objects (numpy's own errors on them
    name neither the problem nor the fix)."""
    if isinstance(demos, str | bytes | os.PathLike):
        raise TypeError(
            f"demos must be arrays of observations (T_i + 1, obs_dim), not the file name "
            f"{os.fsdecode(demos)!r}: {LOAD_DEMOS}"
        )
    if isinstance(demos, DemoFile):
        raise TypeError(
            "demos must be arrays of observations (T_i + 1, obs_dim), not a DemoFile: pass "
            "[e.observations for e in demo_file.episodes]"
        )
    if isinstance(demos, Episode):
        raise TypeError("demos must be a list of observation arrays: pass [episode.observations]")
    if isinstance(demos, np.ndarray):
        return
    if not isinstance(demos, Iterable):
        raise TypeError(
            "demos must be a list of arrays of observations (T_i + 1, obs_dim), got "
            f"{type(demos).__name__}"
        )
    if not isinstance(demos, Sequence):  # a generator: its items are checked as they come
        return
    for i, demo in enumerate(demos):
        if isinstance(demo, Episode):
            raise TypeError(
                f"demo {i} is an Episode, not an array: pass [e.observations for e in episodes]"
            )
        if isinstance(demo, str | bytes | os.PathLike | DemoFile):
            raise TypeError(
                f"demo {i} is a {type(demo).__name__}, not an array of observations: {LOAD_DEMOS}"
            )


def check_demos(demos: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Validate expert demonstrations: a non-empty list of finite (T_i + 1, obs_dim) arrays.
    A TypeError says what to pass for a file name, a ``DemoFile`` or ``Episode`` objects."""
    check_demo_types(demos)
    if isinstance(demos, np.ndarray):
        demos = [demos] if demos.ndim == 2 else list(demos)
    arrays = []
    for i, demo in enumerate(demos):
        try:
            arrays.append(np.asarray(demo, dtype=np.float64))
        except (TypeError, ValueError) as err:  # a dict, a ragged list, a str inside a list
            raise TypeError(
                f"demo {i} is not an array of numbers (a {type(demo).__name__}: {err}); each "
                "demo is one episode's observations, an array (T_i + 1, obs_dim)"
            ) from None
    demos = arrays
    if not demos:
        raise ValueError("at least one expert demonstration is needed")
    for i, demo in enumerate(demos):
        _check_episode(demo, f"demo {i}")
    dims = {d.shape[1] for d in demos}
    if len(dims) > 1:
        raise ValueError(f"demonstrations have different observation dimensions: {sorted(dims)}")
    return demos


def check_episode(observations: np.ndarray, obs_dim: int) -> np.ndarray:
    """Validate one learner episode (T + 1, obs_dim) against the demos' dimension."""
    observations = np.asarray(observations, dtype=np.float64)
    _check_episode(observations, "learner episode")
    if observations.shape[1] != obs_dim:
        raise ValueError(
            f"learner observations have dimension {observations.shape[1]}, "
            f"the demonstrations {obs_dim}"
        )
    return observations


def _check_episode(observations: np.ndarray, what: str) -> None:
    if observations.ndim != 2:
        raise ValueError(
            f"{what} must be a 2-D array (T + 1, obs_dim), got shape {observations.shape}"
        )
    if observations.shape[0] < 2:
        raise ValueError(
            f"{what} needs at least 2 observations (one transition), got {observations.shape[0]}"
        )
    if observations.shape[1] == 0:
        raise ValueError(f"{what} has observations of dimension 0")
    if not np.isfinite(observations).all():
        raise ValueError(f"{what} contains NaN or inf")
