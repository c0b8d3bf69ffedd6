"""Episode-aware ring buffer whose storage lives in JAX arrays.

The arrays (a ``ReplayData``) are what the agents' jitted ``update`` receives: it samples batches
from them inside ``jax.lax.scan``, so nothing is copied from host to device per update.

Whole episodes are written at once (the training loop knows an episode's rewards only at its end),
through one jitted scatter with donated buffers, so writing is in place and handles wrap-around.
Rewards can also be written later with ``relabel``, for a loop that learns its reward after
collecting (``ilfo train`` computes each episode's OT rewards before writing it, so it does
not). ``save``/``load`` use ``.npz`` files without pickle.

Conventions, for a buffer of capacity N:

- ``obs``, ``next_obs``: (N, obs_dim) float32; ``action``: (N, action_dim) float32;
  ``reward``: (N,) float32; ``not_done``: (N,) float32, 0 only after a true termination
  (a time-limit truncation keeps bootstrapping, so it stays 1).
- Slots ``[0, size)`` hold data until the buffer has wrapped once; from then on all N do.
- Episodes get consecutive integer ids (0, 1, 2, ...) in insertion order. An episode is
  *evicted* from the bookkeeping as soon as one of its slots is overwritten (the rest of its
  transitions may still be sampled until they are overwritten too); evicted episodes can no
  longer be read back or relabelled.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Sequence
from functools import partial
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from ilfo.files import load_npz

__all__ = ["ReplayBuffer", "ReplayData", "sample_batch"]

SCHEMA_VERSION = 1
_MIN_PAD = 16


class ReplayData(NamedTuple):
    """The arrays of a replay buffer (a pytree), or a batch drawn from it.

    Shapes are given for a buffer of capacity N; a batch has B in place of N.
    """

    obs: jax.Array
    """(N, obs_dim) observation s_t."""
    action: jax.Array
    """(N, action_dim) action a_t."""
    reward: jax.Array
    """(N,) reward r_t."""
    next_obs: jax.Array
    """(N, obs_dim) observation s_{t+1}."""
    not_done: jax.Array
    """(N,) 1.0 where the TD target bootstraps from s_{t+1}, 0.0 after a true termination."""


def sample_batch(
    data: ReplayData, size: jax.Array | int, key: jax.Array, batch_size: int
) -> ReplayData:
    """Draw ``batch_size`` transitions uniformly, with replacement, from slots ``[0, size)``.

    Pure and jittable (``size`` may be traced, ``batch_size`` must be static).
    Returns a ``ReplayData`` whose arrays have leading dimension ``batch_size``.
    """
    idx = jax.random.randint(key, (batch_size,), 0, size)
    return jax.tree.map(lambda x: x[idx], data)


@partial(jax.jit, donate_argnums=0)
def _scatter(data: ReplayData, chunk: ReplayData, idx: jax.Array) -> ReplayData:
    # Indices equal to N (padding) are out of bounds and dropped.
    return jax.tree.map(lambda d, c: d.at[idx].set(c, mode="drop"), data, chunk)


@partial(jax.jit, donate_argnums=0)
def _scatter_rewards(reward: jax.Array, idx: jax.Array, values: jax.Array) -> jax.Array:
    return reward.at[idx].set(values, mode="drop")


def _padded_length(n: int) -> int:
    """Bucket lengths to powers of two so that the jitted writers compile only a few times."""
    return max(_MIN_PAD, 1 << (n - 1).bit_length())


def _pad(x: np.ndarray, length: int, fill: float | int = 0) -> np.ndarray:
    pad = [(0, length - x.shape[0])] + [(0, 0)] * (x.ndim - 1)
    return np.pad(x, pad, constant_values=fill)


class ReplayBuffer:
    """Ring buffer of transitions, written one whole episode at a time.

    Args:
        capacity: number of transitions N kept; the oldest are overwritten first.
        obs_dim: observation size (including a time feature, if the agent uses one).
        action_dim: action size.

    The buffer object is mutable bookkeeping around immutable JAX arrays: ``data`` is replaced by
    every write, and the previous arrays are donated (invalid afterwards), so do not keep
    references to an old ``data`` across writes.
    """

    def __init__(self, capacity: int, obs_dim: int, action_dim: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be positive, got {capacity}")
        self.capacity = int(capacity)
        self.obs_dim = int(obs_dim)
        self.action_dim = int(action_dim)
        self.data = ReplayData(
            obs=jnp.zeros((capacity, obs_dim), jnp.float32),
            action=jnp.zeros((capacity, action_dim), jnp.float32),
            reward=jnp.zeros((capacity,), jnp.float32),
            next_obs=jnp.zeros((capacity, obs_dim), jnp.float32),
            not_done=jnp.zeros((capacity,), jnp.float32),
        )
        self.size = 0
        """Number of filled slots (at most ``capacity``)."""
        self.ptr = 0
        """Slot where the next episode starts."""
        self.num_episodes = 0
        """Episodes ever inserted; also the id the next episode will get."""
        self._episodes: OrderedDict[int, tuple[int, int]] = OrderedDict()

    def __len__(self) -> int:
        return self.size

    @property
    def episodes(self) -> dict[int, tuple[int, int]]:
        """Live (not evicted) episodes: id -> (start slot, length), oldest first."""
        return dict(self._episodes)

    def add_episode(
        self,
        observations: ArrayLike,
        actions: ArrayLike,
        rewards: ArrayLike | None = None,
        terminated: bool = False,
    ) -> int:
        """Write one episode and return its id.

        Args:
            observations: (T+1, obs_dim) s_0 .. s_T.
            actions: (T, action_dim) a_0 .. a_{T-1}.
            rewards: (T,) r_0 .. r_{T-1}, or None to write zeros and ``relabel`` later.
            terminated: True to cut bootstrapping at s_T (its transition gets ``not_done = 0``):
                a true termination, or the end of a fixed-horizon episode as the paper's code
                does; False for a time-limit truncation in standard episodes.
        """
        obs = np.asarray(observations, dtype=np.float32)
        act = np.asarray(actions, dtype=np.float32)
        t = act.shape[0]
        if obs.shape != (t + 1, self.obs_dim):
            raise ValueError(f"observations must be {(t + 1, self.obs_dim)}, got {obs.shape}")
        if act.shape != (t, self.action_dim):
            raise ValueError(f"actions must be {(t, self.action_dim)}, got {act.shape}")
        if not 1 <= t <= self.capacity:
            raise ValueError(f"episode length {t} must be in [1, capacity={self.capacity}]")
        rew = np.zeros(t, np.float32) if rewards is None else np.asarray(rewards, np.float32)
        if rew.shape != (t,):
            raise ValueError(f"rewards must be {(t,)}, got {rew.shape}")
        not_done = np.ones(t, np.float32)
        if terminated:
            not_done[-1] = 0.0

        # Evict the oldest episodes whose slots the write range [ptr, ptr + t) overlaps.
        while self._episodes:
            oldest_id, (start, _) = next(iter(self._episodes.items()))
            if (start - self.ptr) % self.capacity >= t:
                break
            del self._episodes[oldest_id]

        length = _padded_length(t)
        idx = (self.ptr + np.arange(t)) % self.capacity
        # numpy arrays in ReplayData's fields (obs, action, reward, next_obs, not_done, in this
        # order): the jitted _scatter takes them in as jax.Arrays.
        host = [_pad(x, length) for x in (obs[:-1], act, rew, obs[1:], not_done)]
        chunk = ReplayData(*cast(list[jax.Array], host))
        self.data = _scatter(self.data, chunk, _pad(idx, length, fill=self.capacity))

        episode_id = self.num_episodes
        self._episodes[episode_id] = (self.ptr, t)
        self.num_episodes += 1
        self.ptr = (self.ptr + t) % self.capacity
        self.size = min(self.size + t, self.capacity)
        return episode_id

    def _slots(self, episode_id: int) -> np.ndarray:
        if episode_id not in self._episodes:
            raise KeyError(f"episode {episode_id} is not in the buffer (never added or evicted)")
        start, length = self._episodes[episode_id]
        return (start + np.arange(length)) % self.capacity

    def relabel(self, episode_ids: Sequence[int], rewards: Sequence[ArrayLike]) -> None:
        """Overwrite the rewards of whole episodes.

        Args:
            episode_ids: ids returned by ``add_episode``; each must still be live.
            rewards: one (T_i,) array per episode, T_i its length.
        """
        if len(episode_ids) != len(rewards):
            raise ValueError("need one reward array per episode id")
        if len(episode_ids) == 0:
            return
        all_idx, all_rew = [], []
        for episode_id, rew in zip(episode_ids, rewards, strict=True):
            idx = self._slots(int(episode_id))
            rew = np.asarray(rew, np.float32)
            if rew.shape != idx.shape:
                raise ValueError(f"episode {episode_id} has {idx.size} steps, got {rew.shape}")
            all_idx.append(idx)
            all_rew.append(rew)
        idx, rew = np.concatenate(all_idx), np.concatenate(all_rew)
        length = _padded_length(idx.size)
        reward = _scatter_rewards(
            self.data.reward, _pad(idx, length, fill=self.capacity), _pad(rew, length)
        )
        self.data = self.data._replace(reward=reward)

    def episode(self, episode_id: int) -> dict[str, np.ndarray]:
        """Read a live episode back as numpy arrays.

        Returns a dict with ``observations`` (T+1, obs_dim), ``actions`` (T, action_dim),
        ``rewards`` (T,) and ``not_done`` (T,).
        """
        idx = jnp.asarray(self._slots(episode_id))
        obs = np.asarray(self.data.obs[idx])
        last = np.asarray(self.data.next_obs[idx[-1]])[None]
        return {
            "observations": np.concatenate([obs, last]),
            "actions": np.asarray(self.data.action[idx]),
            "rewards": np.asarray(self.data.reward[idx]),
            "not_done": np.asarray(self.data.not_done[idx]),
        }

    def sample(self, key: jax.Array, batch_size: int) -> ReplayData:
        """Uniform batch of ``batch_size`` transitions from filled slots (``sample_batch``)."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty buffer")
        return sample_batch(self.data, self.size, key, batch_size)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the buffer to an ``.npz`` file (no pickle); only filled slots are stored."""
        ids = np.array(list(self._episodes), dtype=np.int64)
        spans = np.array(list(self._episodes.values()), dtype=np.int64).reshape(-1, 2)
        arrays: dict[str, Any] = {
            name: np.asarray(value[: self.size]) for name, value in self.data._asdict().items()
        }
        np.savez(
            path,
            schema_version=np.int64(SCHEMA_VERSION),
            capacity=np.int64(self.capacity),
            obs_dim=np.int64(self.obs_dim),
            action_dim=np.int64(self.action_dim),
            size=np.int64(self.size),
            ptr=np.int64(self.ptr),
            num_episodes=np.int64(self.num_episodes),
            episode_ids=ids,
            episode_starts=spans[:, 0],
            episode_lengths=spans[:, 1],
            **arrays,
        )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ReplayBuffer:
        """Read a buffer written by ``save``; a damaged file is a ValueError naming it."""
        f = load_npz(path, "replay buffer")
        try:
            version = int(f["schema_version"])
            if version != SCHEMA_VERSION:
                raise ValueError(f"replay file schema {version}, expected {SCHEMA_VERSION}")
            buf = cls(int(f["capacity"]), int(f["obs_dim"]), int(f["action_dim"]))
            size = int(f["size"])
            buf.data = ReplayData(
                **{name: jnp.asarray(_pad(f[name], buf.capacity)) for name in ReplayData._fields}
            )
            buf.size, buf.ptr, buf.num_episodes = size, int(f["ptr"]), int(f["num_episodes"])
            for episode_id, start, length in zip(
                f["episode_ids"], f["episode_starts"], f["episode_lengths"], strict=True
            ):
                buf._episodes[int(episode_id)] = (int(start), int(length))
        except (KeyError, ValueError, TypeError) as err:
            raise ValueError(f"{path} is not a readable replay buffer ({err})") from None
        return buf
