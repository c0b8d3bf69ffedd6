"""ilfo's episode rewards in Stable-Baselines3 (and sbx): a replay buffer that relabels each
episode when it ends.

OOPS's reward of a step depends on the whole episode (it is the step's share of the episode's
optimal transport to the expert), so it exists only once the episode has ended. The SB3
maintainers' advice for rewards known at an episode's end is to rewrite the replay buffer
(DLR-RM/stable-baselines3 issue 1370); ``OTReplayBuffer`` does it where the rows are written:

- ``add`` stores every transition with reward 0, whatever the environment gave (the task
  reward never reaches the learner), and tracks each env's running episode (its rows, in that
  env's column of the buffer, across the ring's wrap-around);
- when an env's episode ends (``done``), the episode's observations are read back from the
  buffer (the terminal observation included: SB3 stores it as that row's next observation),
  the reward function rewards them, and the rewards are written into exactly those rows,
  which become *ready*;
- ``sample`` draws only ready rows: rows of episodes still running (whose rewards do not exist
  yet) are never learned from. SB3 trains after it stores a step, so every gradient step sees
  every finished episode's rewards.

Works with SB3's off-policy algorithms (SAC, TD3, DDPG; TQC and CrossQ from sb3-contrib) and
sbx's, with one env or a VecEnv of several (episodes ending at different times), for flat Box
observations; ``optimize_memory_usage`` is refused (it drops the terminal observation that the
last step's reward needs).

    from ilfo.integrations.sb3 import OTReplayBuffer
    from ilfo.rewards import OOPS

    model = SAC("MlpPolicy", env, replay_buffer_class=OTReplayBuffer,
                replay_buffer_kwargs={"reward": OOPS(demos)}, learning_starts=1000)

``examples/sb3_oops.py`` runs OOPS + SAC on Hopper-v5 with the paper's fixed horizon and time
feature (``observation_columns`` hides the time feature from the reward).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

try:
    from gymnasium import spaces
    from stable_baselines3.common.buffers import ReplayBuffer
    from stable_baselines3.common.type_aliases import ReplayBufferSamples
except ImportError as err:  # pragma: no cover - depends on the optional extra
    raise ImportError(
        "ilfo.integrations.sb3 needs Stable-Baselines3: pip install -e '.[sb3]'"
    ) from err

EpisodeReward = Callable[[np.ndarray], Any]
"""Observations (T + 1, d) of one episode -> its rewards (T,), as an array or as an object
with ``.rewards`` (ilfo's ``OOPS``, ``PWIL`` and any ``EpisodeRewarder``)."""


class OTReplayBuffer(ReplayBuffer):
    """SB3's ``ReplayBuffer`` with each episode's rewards from ``reward`` (see the module).

    Args (besides SB3's):
        reward: The episode reward: observations (T + 1, d) -> rewards (T,). Where it has an
            ``obs_dim`` (ilfo's rewards: its demos' dimension), d must equal it.
        observation_columns: Give the reward only the first this many columns of each
            observation (e.g. the env's own ones, without an appended time feature); None: all.
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: Any = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
        *,
        reward: EpisodeReward,
        observation_columns: int | None = None,
    ) -> None:
        if optimize_memory_usage:
            raise ValueError(
                "OTReplayBuffer needs optimize_memory_usage=False: the memory-saving buffer "
                "does not keep an episode's terminal observation, which its last reward needs"
            )
        if not isinstance(observation_space, spaces.Box) or len(observation_space.shape) != 1:
            raise ValueError(f"OTReplayBuffer needs flat Box observations, got {observation_space}")
        if not callable(reward):
            raise ValueError(f"reward must be callable (an episode reward), got {reward!r}")
        width = observation_space.shape[0]
        if observation_columns is not None:
            if isinstance(observation_columns, bool) or not isinstance(
                observation_columns, int | np.integer
            ):
                raise ValueError(
                    "observation_columns must be an int (how many leading columns of each "
                    f"observation the reward sees) or None, got {observation_columns!r}"
                )
            observation_columns = int(observation_columns)
            if not 1 <= observation_columns <= width:
                raise ValueError(
                    f"observation_columns must be between 1 and {width}, got {observation_columns}"
                )
        _check_reward_width(reward, width, observation_columns)
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device=device,
            n_envs=n_envs,
            optimize_memory_usage=False,
            handle_timeout_termination=handle_timeout_termination,
        )
        self.reward = reward
        self.observation_columns = observation_columns
        self.ready = np.zeros((self.buffer_size, self.n_envs), dtype=bool)
        """Rows (row, env) whose rewards are their episode's: the only ones sampled."""
        self.ready_count = 0
        """``ready.sum()``, kept as rows change (``sample`` runs every gradient step)."""
        self.episode_steps = np.zeros(self.n_envs, dtype=np.int64)
        """Steps of each env's running episode stored so far."""
        self.episodes_labelled = 0
        self._warned_long_episode = False

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        row = self.pos
        self._drop_abandoned_episodes(obs)
        self.ready_count -= int(self.ready[row].sum())
        self.ready[row] = False  # a row written again belongs to a new, running episode
        super().add(obs, next_obs, action, np.zeros_like(reward), done, infos)
        self.episode_steps += 1
        for env in np.flatnonzero(np.asarray(done).reshape(-1)):
            self._label_episode(int(env), row)
            self.episode_steps[env] = 0

    def _drop_abandoned_episodes(self, obs: np.ndarray) -> None:
        """Forget a running episode that this step does not continue: a second ``learn()``
        resets the envs mid-episode, and its next episode would be glued onto the abandoned
        rows (rewarded as one episode, a jump between unrelated states coupled as a
        transition). The abandoned rows stay unready until overwritten."""
        if not self.episode_steps.any():
            return
        stored = np.asarray(obs, dtype=self.observations.dtype).reshape(self.n_envs, -1)
        previous = self.next_observations[(self.pos - 1) % self.buffer_size].reshape(
            self.n_envs, -1
        )
        same = stored == previous
        if not same.all():  # NaN == NaN counts as the same observation
            same |= np.isnan(stored) & np.isnan(previous)
        self.episode_steps[~same.all(axis=1)] = 0

    def reset(self) -> None:
        """Empty the buffer (SB3's reset), its ready rows and running episodes with it."""
        super().reset()
        self.ready[:] = False
        self.ready_count = 0
        self.episode_steps[:] = 0

    def _label_episode(self, env: int, last_row: int) -> None:
        steps = int(min(self.episode_steps[env], self.buffer_size))  # longer: its start is gone
        if self.episode_steps[env] > self.buffer_size and not self._warned_long_episode:
            self._warned_long_episode = True
            warnings.warn(
                f"an episode of {self.episode_steps[env]} steps is longer than the replay "
                f"buffer's {self.buffer_size} rows per env: it is rewarded, as an episode of "
                f"its own, on its last {self.buffer_size} steps only (the rest is overwritten); "
                "set a larger buffer_size (at least the longest episode's steps times n_envs) "
                "to reward whole episodes. Warned once.",
                stacklevel=3,
            )
        rows = (last_row - steps + 1 + np.arange(steps)) % self.buffer_size
        observations = np.concatenate(
            [self.observations[rows, env], self.next_observations[last_row, env][None]]
        ).astype(np.float64)
        if self.observation_columns is not None:
            observations = observations[:, : self.observation_columns]
        try:
            out = self.reward(observations)
        except ValueError as err:
            width_checked = isinstance(getattr(self.reward, "obs_dim", None), int | np.integer)
            if width_checked or self.observation_columns is not None:
                raise  # the hint below would not help
            raise ValueError(
                f"the reward refused an episode of {steps} steps with observations of "
                f"{observations.shape[1]} columns ({err}); if it expects fewer (e.g. not an "
                "appended time feature), set the buffer's observation_columns"
            ) from err
        rewards = np.asarray(getattr(out, "rewards", out), dtype=np.float64).reshape(-1)
        if rewards.shape != (steps,):
            raise ValueError(
                f"the reward gave {rewards.shape[0]} rewards for an episode of {steps} steps"
            )
        if not np.isfinite(rewards).all():
            where = np.flatnonzero(~np.isfinite(rewards))
            raise ValueError(
                f"the reward function returned NaN or inf for an episode of {steps} steps (at "
                f"steps {where[:5].tolist()}{', ...' if len(where) > 5 else ''}; the episode's "
                f"observations are {'' if np.isfinite(observations).all() else 'not '}finite): "
                "the buffer would train on them; fix the reward (or the env's observations)"
            )
        self.rewards[rows, env] = rewards
        self.ready_count += steps  # the running episode's rows: none was ready
        self.ready[rows, env] = True
        self.episodes_labelled += 1

    def sample(self, batch_size: int, env: Any = None) -> ReplayBufferSamples:
        """``batch_size`` transitions drawn uniformly from the ready rows."""
        filled = self.buffer_size if self.full else self.pos
        ready = self.ready[:filled]
        count = self.ready_count
        if count == 0:
            raise ValueError(
                "no episode has ended yet, so no transition has its reward: set the "
                "algorithm's learning_starts to at least one episode's steps"
            )
        # SB3's global generator, as its own sampling (seeded by the algorithm's seed).
        randint = np.random.randint
        if count * 2 >= ready.size:  # mostly ready: draw all, redraw the few that are not
            rows = randint(0, filled, size=batch_size)
            envs = randint(0, self.n_envs, size=batch_size)
            bad = ~ready[rows, envs]
            while bad.any():
                rows[bad] = randint(0, filled, size=int(bad.sum()))
                envs[bad] = randint(0, self.n_envs, size=int(bad.sum()))
                bad = ~ready[rows, envs]
        else:
            rows, envs = np.divmod(
                np.flatnonzero(ready)[randint(0, count, batch_size)], self.n_envs
            )
        return self._samples(rows, envs, env)

    def _samples(self, rows: np.ndarray, envs: np.ndarray, env: Any) -> ReplayBufferSamples:
        # Dones that are time limits are not terminations (SB3's handle_timeout_termination).
        dones = self.dones[rows, envs] * (1 - self.timeouts[rows, envs])
        data = (
            self._normalize_obs(self.observations[rows, envs, :], env),
            self.actions[rows, envs, :],
            self._normalize_obs(self.next_observations[rows, envs, :], env),
            dones.reshape(-1, 1),
            self._normalize_reward(self.rewards[rows, envs].reshape(-1, 1), env),
        )
        return ReplayBufferSamples(*tuple(map(self.to_torch, data)))


def _check_reward_width(reward: Any, width: int, observation_columns: int | None) -> None:
    """Where the reward knows its demos' dimension (``obs_dim``), refuse now the observations
    of another width that it would refuse only when the first episode ends, inside ``learn``."""
    obs_dim = getattr(reward, "obs_dim", None)
    if isinstance(obs_dim, bool) or not isinstance(obs_dim, int | np.integer):
        return  # not known: the reward checks each episode itself
    given = width if observation_columns is None else observation_columns
    if given == obs_dim:
        return
    problem = (
        f"the reward's demonstrations have observations of dimension {obs_dim}, but the "
        f"buffer would give it {given} columns of each observation"
    )
    if obs_dim == width:
        raise ValueError(f"{problem}: leave observation_columns None to give it all {width}")
    if obs_dim < width:
        raise ValueError(
            f"{problem}: set observation_columns={obs_dim} to give it the first {obs_dim} (e.g. "
            "the env's own, without an appended time feature such as TimeFeature's)"
        )
    raise ValueError(
        f"{problem}, {width} in all: the env's observations are narrower than the demos'; "
        "use demonstrations recorded in this env"
    )
