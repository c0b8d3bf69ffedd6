"""Offline labelling: every episode of an offline dataset rewarded by optimal transport to
state-only demos, for offline RL (IQL and others), as OTR does (Luo et al., "Optimal Transport
for Offline Imitation Learning", ICLR 2023).

For each episode and each demo, OOPS's coupling of the episode's atoms (its transitions, by
default) with the demo's gives each step a transported cost c_t; the step's reward against
that demo is ``squash(-c_t)``: ``oops`` (OOPS's own reward, -reward_scale * T / sqrt(d) * c_t,
what ilfo's agents learn from), ``linear`` (alpha * -c_t) or ``exponential`` (alpha *
exp(beta * -c_t), OTR's choice for locomotion, alpha = beta = 5). For these two, as in OTR,
every step carries the mass 1/H of an ``episode_length`` H (default: the longest demo's), so
c_t is the step's cost at that mass: an episode shorter than H is not penalised for its
length (with uniform masses 1/T, every cost of a T-step episode would grow by H/T). With
several demos, the episode's rewards are the mean over the ``top_k`` demos whose rewards sum
highest (OTR's aggregation; top_k 1: the best-matching demo). Episodes are independent:
they are labelled in parallel over ``workers`` processes.

Formats (read by ``ilfo.demos.load_any``, written back in kind): ilfo ``.npz``, Minari HDF5
datasets (a copy of the dataset directory given, each ``episode_<i>/rewards`` replaced; given
its HDF5 file alone, a copy of that file) and D4RL HDF5 files (a copy, ``rewards`` replaced
row by row). Ant-v5 and Humanoid-v5 states are compared without the contact forces that end
their observations, as ilfo's imitation observes them (``contact_forces``); the output keeps
every column. A D4RL file without
``next_observations`` has no transition for the last row of each episode: that row gets the
reward of the episode's last labelled step (and a one-row episode, none at all, 0).
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import re
import shutil
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ilfo.envs import CONTACT_FORCE_DIMS, FULL_OBSERVATION_DIMS, match_observation_width
from ilfo.ranges import check_fields, count, positive
from ilfo.rewards import OOPS, OOPSConfig
from ilfo.threads import THREAD_VARIABLES
from ilfo.training.config import imitation_drops_contact_forces

Squashing = Literal["oops", "linear", "exponential"]


@dataclass(frozen=True)
class LabelConfig:
    """How episodes are rewarded."""

    oops: OOPSConfig = field(default_factory=OOPSConfig)
    """The OT problem: atoms, cost, solver, lambda, standardisation (the paper's defaults);
    ``demo_selection`` and ``seed`` are not used (every demo is solved, then ``top_k``)."""
    squashing: Squashing = "exponential"
    """``oops`` (OOPS's reward scale), ``linear`` (alpha * -c) or ``exponential``
    (alpha * exp(beta * -c), OTR's)."""
    alpha: float = positive(5.0)
    """Scale of the linear and exponential squashing (OTR: 5 for exponential, 10 for
    linear); > 0, as ``beta``: <= 0 would reward the episodes far from the demos most."""
    beta: float = positive(5.0)
    """Rate of the exponential squashing (OTR: 5)."""
    top_k: int = count(1)
    """Demos averaged: the k whose rewards of the episode sum highest (OTR's top-k)."""
    episode_length: int | None = count(None)
    """H: the linear and exponential squashings see each step's cost at the mass 1/H, as OTR
    (its ``episode_length``, 1000 on MuJoCo); None: the longest demo's transitions."""

    def __post_init__(self) -> None:
        # Types and ranges, from the fields' declarations (ilfo.ranges), named with the flags
        # of ``ilfo label``.
        check_fields(self, flags="")
        if self.oops.kernel != "linear":
            raise ValueError(
                "the labeller turns costs into rewards by its squashing (squashing, alpha, beta),"
                f" not by oops.kernel; leave oops.kernel linear, got {self.oops.kernel!r}"
            )


class EpisodeLabeller:
    """``EpisodeLabeller(demos, config)(observations) -> rewards (T,)``."""

    def __init__(self, demos: Sequence[np.ndarray], config: LabelConfig | None = None) -> None:
        self.config = config or LabelConfig()
        if self.config.top_k > len(demos):
            raise ValueError(f"top_k {self.config.top_k} exceeds the {len(demos)} demos given")
        self.oops = OOPS(demos, dataclasses.replace(self.config.oops, warm_start=False))
        self.episode_length = self.config.episode_length or max(len(d) - 1 for d in demos)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        cfg = self.config
        couplings = self.oops.couplings(observations)
        costs = np.stack([c.row_costs for c in couplings])  # (demos, T), rows of mass 1/T
        if cfg.squashing == "oops":
            scale = cfg.oops.reward_scale * costs.shape[1] / np.sqrt(self.oops.obs_dim)
            rewards = -scale * costs
        else:
            costs = costs * (costs.shape[1] / self.episode_length)  # rows of mass 1/H
            if cfg.squashing == "linear":
                rewards = cfg.alpha * -costs
            else:
                rewards = cfg.alpha * np.exp(cfg.beta * -costs)
        best = np.argsort(-rewards.sum(axis=1), kind="stable")[: cfg.top_k]
        return rewards[best].mean(axis=0)


@dataclass(frozen=True)
class LabelSummary:
    """What ``label_dataset`` did."""

    out: Path
    format: str
    episodes: int
    transitions: int
    seconds: float
    reward_mean: float
    reward_std: float


_WORKER: dict[str, Any] = {}


def _init_worker(demos: list[np.ndarray], config: LabelConfig) -> None:
    _WORKER["labeller"] = EpisodeLabeller(demos, config)


def _label_chunk(chunk: list[np.ndarray]) -> list[np.ndarray]:
    return [_WORKER["labeller"](obs) for obs in chunk]


def label_episodes(
    episodes: Sequence[np.ndarray],
    demos: Sequence[np.ndarray],
    config: LabelConfig | None = None,
    *,
    workers: int = 1,
    on_progress: Callable[[int], None] | None = None,
) -> list[np.ndarray]:
    """Rewards (T_i,) of each episode's observations (T_i + 1, d), over ``workers``
    processes (1: in this process). ``on_progress(n)`` after each chunk of n episodes."""
    config = config or LabelConfig()
    demos = [np.asarray(d, np.float64) for d in demos]
    labeller = EpisodeLabeller(demos, config)  # bad settings fail here, not in a worker
    if workers <= 1:
        out = []
        for obs in episodes:
            out.append(labeller(obs))
            if on_progress:
                on_progress(1)
        return out
    size = max(1, min(32, len(episodes) // (4 * workers) or 1))
    chunks = [list(episodes[i : i + size]) for i in range(0, len(episodes), size)]
    results: list[np.ndarray] = []
    # Fresh (spawned) workers with one BLAS thread each: side by side, OpenBLAS's default pools
    # oversubscribe the cores and slow every solve 10x (bench/label.py).
    saved = {k: os.environ.get(k) for k in THREAD_VARIABLES}
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))
    try:
        with ProcessPoolExecutor(
            workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(demos, config),
        ) as pool:
            for chunk, labelled in zip(chunks, pool.map(_label_chunk, chunks), strict=True):
                results.extend(labelled)
                if on_progress:
                    on_progress(len(chunk))
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return results


def label_dataset(
    dataset: str | Path,
    demos_file: str | Path,
    out: str | Path,
    config: LabelConfig | None = None,
    *,
    num_demos: int | None = None,
    env_id: str | None = None,
    contact_forces: bool | None = None,
    workers: int = 1,
    on_progress: Callable[[int], None] | None = None,
) -> LabelSummary:
    """Label every episode of ``dataset`` with OT rewards from the first ``num_demos`` (all:
    None) demos of ``demos_file``, and write the dataset to ``out`` in its own format (see the
    module). ``out`` must not exist (nothing is overwritten), and its folder must.
    ``contact_forces``: compare Ant-v5's and Humanoid-v5's states with their contact forces
    (None: as ilfo's imitation does, without). The dataset's and the demos' environments, where
    both are named, must be one task (versions may differ: D4RL's Hopper-v2 and Hopper-v5)."""
    dataset, out = Path(dataset), Path(out)
    fmt = _output_format(dataset, out)
    data, episodes, expert_obs = _episodes_and_demos(
        dataset, demos_file, num_demos, env_id, contact_forces
    )
    start = time.perf_counter()
    rewards = label_episodes(
        episodes,
        expert_obs,
        config,
        workers=workers,
        on_progress=on_progress,
    )
    seconds = time.perf_counter() - start
    _write_new(fmt, dataset, out, data, rewards)
    flat = np.concatenate(rewards)
    return LabelSummary(
        out, fmt, len(rewards), int(flat.size), seconds, float(flat.mean()), float(flat.std())
    )


def _output_format(dataset: Path, out: Path) -> str:
    """The dataset's format, which its labelled copy is written in, or an error saying why
    ``out`` cannot be written."""
    from ilfo.demos.readers import detect_format

    if out.exists():
        raise FileExistsError(f"{out} exists: labelling writes a new file or directory")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{out}: its folder {out.parent} does not exist")
    fmt = detect_format(dataset)
    if fmt not in ("ilfo", "minari", "d4rl"):
        raise ValueError(f"{dataset}: labelling writes ilfo, Minari or D4RL files, not {fmt}")
    if fmt == "ilfo" and out.suffix != ".npz":
        raise ValueError(f"{out}: an ilfo dataset is written as a .npz file")
    return fmt


def _episodes_and_demos(
    dataset: Path,
    demos_file: str | Path,
    num_demos: int | None,
    env_id: str | None,
    contact_forces: bool | None,
) -> tuple[Any, list[np.ndarray], list[np.ndarray]]:
    """The dataset as read, its episodes' observations and the demos', as OT compares them
    (checked to be of one task and one width)."""
    from ilfo import demos as demo_io

    data = demo_io.load_any(dataset, env_id=env_id)
    expert = demo_io.load_any(demos_file)
    if not expert.episodes:
        raise ValueError(f"{demos_file}: no demos")
    if data.env_id and expert.env_id and _task(data.env_id) != _task(expert.env_id):
        raise ValueError(
            f"{demos_file} holds demos of {expert.env_id}, {dataset} episodes of "
            f"{data.env_id}: labelling compares the states of one task"
        )
    if num_demos is not None and not 1 <= num_demos <= len(expert.episodes):
        raise ValueError(
            f"num_demos must be between 1 and {len(expert.episodes)} (the demos in "
            f"{demos_file}), got {num_demos}"
        )
    expert_obs = [e.observations for e in expert.episodes[:num_demos]]
    if expert_obs[0].shape[1] != data.episodes[0].observations.shape[1]:
        raise ValueError(
            f"{demos_file} has {expert_obs[0].shape[1]}-dim observations, {dataset} has "
            f"{data.episodes[0].observations.shape[1]}"
        )
    episodes = [e.observations for e in data.episodes]
    env = expert.env_id or data.env_id
    if imitation_drops_contact_forces(env, contact_forces):  # files already without them stay so
        width = FULL_OBSERVATION_DIMS[env] - CONTACT_FORCE_DIMS[env]
        episodes = [match_observation_width(obs, env, width) for obs in episodes]
        expert_obs = [match_observation_width(obs, env, width) for obs in expert_obs]
    return data, episodes, expert_obs


def _write_new(fmt: str, dataset: Path, out: Path, data: Any, rewards: list[np.ndarray]) -> None:
    writers = {"ilfo": _write_ilfo, "minari": _write_minari, "d4rl": _write_d4rl}
    # Written beside ``out`` and moved into place: an error or a kill midway leaves no
    # half-labelled file under the labelled name (and the name free for a retry).
    partial = out.with_name(f".partial-{os.getpid()}-{out.name}")  # its suffix kept
    try:
        writers[fmt](dataset, partial, data, rewards)
        _move_new(partial, out)
    finally:
        if partial.is_dir():
            shutil.rmtree(partial)
        partial.unlink(missing_ok=True)


def _task(env_id: str) -> str:
    """The task an env id names, without its version: hopper-v2 and Hopper-v5 are one."""
    return re.sub(r"-v\d+$", "", env_id).lower()


def _move_new(src: Path, dst: Path) -> None:
    """Move ``src`` to the new name ``dst``, never over a file or directory that appeared
    there meanwhile (a FileExistsError; ``src`` is then left for the caller)."""
    taken = FileExistsError(f"{dst} appeared while labelling: the labels are not written")
    if src.is_dir():
        if dst.exists():  # a directory rename would replace an empty one
            raise taken
        os.rename(src, dst)
        return
    try:
        os.link(src, dst)  # fails if dst exists, atomically
    except FileExistsError:
        raise taken from None
    except OSError:  # a file system without hard links: checked, then renamed
        if dst.exists():
            raise taken from None
        os.replace(src, dst)
        return
    src.unlink()


def _write_ilfo(dataset: Path, out: Path, data: Any, rewards: list[np.ndarray]) -> None:
    from ilfo import demos as demo_io

    episodes = [
        dataclasses.replace(e, rewards=r.astype(np.float64))
        for e, r in zip(data.episodes, rewards, strict=True)
    ]
    provenance = {
        **data.provenance,
        "rewards": "OT labels (ilfo label)",
        "labelled_from": str(dataset),
    }
    demo_io.save(out, episodes, data.env_id, provenance)


def _write_minari(dataset: Path, out: Path, data: Any, rewards: list[np.ndarray]) -> None:
    import h5py

    from ilfo.demos.readers import _minari_file, minari_episode_names

    source = _minari_file(dataset)
    if dataset.is_dir():  # the dataset directory given, its metadata with it
        shutil.copytree(dataset, out)
        target = out / source.relative_to(dataset)
    else:  # its HDF5 file alone: a file, nothing from the folder it sits in
        shutil.copyfile(source, out)
        target = out
    with h5py.File(target, "r+") as f:
        for name, r in zip(minari_episode_names(f), rewards, strict=True):
            if "rewards" in f[name]:
                del f[name]["rewards"]
            f[name].create_dataset("rewards", data=r.astype(np.float64))


def _write_d4rl(dataset: Path, out: Path, data: Any, rewards: list[np.ndarray]) -> None:
    import h5py

    from ilfo.demos.readers import d4rl_spans

    shutil.copyfile(dataset, out)
    with h5py.File(out, "r+") as f:
        n = len(f["observations"])
        done = np.zeros(n, dtype=bool)
        for key in ("terminals", "timeouts"):
            if key in f:
                done |= f[key][()] != 0
        has_next = "next_observations" in f
        column = np.zeros(n, dtype=np.float32)
        for (s, e, stop), r in zip(d4rl_spans(done, has_next), rewards, strict=True):
            column[s:stop] = r
            column[stop:e] = r[-1]  # the last row's transition is unknown: its step's reward
        if "rewards" in f:
            del f["rewards"]
        f.create_dataset("rewards", data=column)
