"""Benchmark the full training loop (`ilfo train`, OOPS + TD3 on Hopper-v5 by default, any
imitation algo with ``--algo``) against the update-only rate: where does a step's time go?

A short ``Trainer`` run (fast preset by default; Hopper-v5; the bundled scripted demos, the
first one imitated; ``--steps`` 20,000 of which ``--start-steps`` 10,000 random; evaluation and
checkpoints pushed past the end of the run) timed through the loop's ``LoopHooks`` (its
``timed`` pieces):

- ``env``: ``trainer.env.step``;
- ``act``: the policy's forward pass and exploration noise, synchronised (``np.asarray``);
- ``reward``: the episode reward of an episode (the OT solve; for a learned reward, its values
  of the episode's transitions, logged as the proxy return; its training is in ``update``);
- ``replay``: ``trainer.buffer.add_episode`` (the hook waits until the scatter is done);
- ``update``: the episode's agent updates (every chunk, synchronised by reading the metrics);
- ``other``: the rest of the learning phase's wall time (the Python loop around ``env.step``:
  per-step PRNG key folding and list appends, time features, metrics.csv, the progress bar).

Figures are over the learning phase (after ``start_steps``), whose ``update`` chunks are compiled
before the run starts, so no compilation is timed. ``steps_per_s`` is learning steps over the
learning phase's wall time; ``update_only_updates_per_s`` is a direct timing of
``update(num_updates=1000)`` on the trained state and the filled buffer, at the same preset
(``loop_vs_update_only`` compares the loop's updates per second with it: the loop's ceiling).
``env_plus_reward_share`` is the share of the learning phase spent in the environment and the
OT reward (target: < 10%).

The OT reward is numpy (OpenBLAS matrix-vector products): on a machine whose cores are busy
(other runs, other seeds), OpenBLAS's threads make it 10-20x slower than single-threaded, so
compare ``OPENBLAS_NUM_THREADS=1 python bench/train.py`` with the default; the setting is
reported.

    python bench/train.py                    # fast preset, table
    python bench/train.py --preset paper     # critics 1024-1024
    python bench/train.py --updates-per-step 2   # two updates per environment step
    python bench/train.py --json             # one JSON line per figure
    python bench/train.py --quick            # 2,000 steps, 1,000 random (a smoke run)
    python bench/train.py --algo opolo       # a baseline's loop
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import date
from pathlib import Path
from typing import Any

import jax
import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.agents import policy_of
from ilfo.benchmarking import machine
from ilfo.paths import bundled_demos
from ilfo.training import LoopHooks, TrainConfig, Trainer

PIECES = ("env", "act", "reward", "replay", "update", "other")


class TimingHooks(LoopHooks):
    """Times the loop's pieces through its hooks (``Trainer(hooks=...)``); counts only the
    learning phase, and records each learning episode's span and Sinkhorn solve."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self.episodes: list[dict[str, Any]] = []
        self.solves: list[tuple[int | None, bool]] = []
        """(iterations, converged) of each learning-phase episode's OT solve."""
        self.active = False
        self._trainer: Trainer | None = None

    @contextmanager
    def timed(self, piece: str) -> Iterator[None]:
        start = time.perf_counter()
        yield
        if piece == "replay" and self._trainer is not None:
            # The write is an async jitted scatter: count the wait for it, not its dispatch.
            jax.block_until_ready(self._trainer.buffer.data)
        if self.active:
            self.seconds[piece] += time.perf_counter() - start
            self.calls[piece] += 1

    def episode_started(self, trainer: Trainer) -> None:
        self._trainer = trainer
        self.active = trainer.step >= trainer.config.start_steps
        self._start = time.perf_counter()

    def episode_rewarded(self, trainer: Trainer, output: Any) -> None:
        if self.active:
            self.solves.append((output.coupling.iterations, bool(output.coupling.converged)))

    def episode_ended(self, trainer: Trainer, row: dict[str, Any]) -> None:
        # The row is written: the span covers the loop's bookkeeping (metrics) too.
        steps = row["step"] - (self.episodes[-1]["step"] if self.episodes else 0)
        self.episodes.append(
            {
                "learning": self.active,
                "start": self._start,
                "end": time.perf_counter(),
                "steps": steps,
                "step": row["step"],
            }
        )
        self.active = False


def update_chunks(num_updates: int) -> list[int]:
    """Every power-of-two chunk ``Trainer._update`` may split an episode's updates into, up to
    ``num_updates`` (a full episode's): episodes that end early (standard episodes) use
    smaller ones."""
    return [1 << b for b in range(num_updates.bit_length() - 1, -1, -1)]


def precompile(trainer: Trainer) -> float:
    """Compile ``act`` and every ``update`` chunk an episode may use; returns the seconds."""
    start = time.perf_counter()
    funcs, state = trainer.agent.functions, trainer.state
    obs = np.zeros(trainer.buffer.obs_dim, np.float32)
    funcs.act(policy_of(state), obs, jax.random.PRNGKey(0)).block_until_ready()
    for chunk in update_chunks(trainer.horizon * trainer.config.updates_per_step):
        out = funcs.update(
            state, trainer.buffer.data, max(trainer.buffer.size, 1), num_updates=chunk
        )
        jax.block_until_ready(out)
    return time.perf_counter() - start


def update_only(trainer: Trainer, num_updates: int, repeat: int) -> float:
    """Best updates/s of ``update(num_updates)`` on the trained state and the filled buffer."""
    update = trainer.agent.functions.update
    state, data, size = trainer.state, trainer.buffer.data, trainer.buffer.size
    state, _ = update(state, data, size, num_updates=num_updates)
    jax.block_until_ready(state)
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        state, metrics = update(state, data, size, num_updates=num_updates)
        jax.block_until_ready((state, metrics))
        best = min(best, time.perf_counter() - start)
    return num_updates / best


def run(args: argparse.Namespace) -> tuple[dict, list[dict]]:
    hooks = TimingHooks()
    with tempfile.TemporaryDirectory(prefix="ilfo-bench-train-") as tmp:
        config = TrainConfig(
            env="Hopper-v5",
            algo=args.algo,
            demos=str(bundled_demos("Hopper-v5-scripted")),
            num_demos=1,
            steps=args.steps,
            start_steps=args.start_steps,
            preset=args.preset,
            seed=args.seed,
            eval_every=10 * args.steps,
            checkpoint_every=10 * args.steps,
            checkpoint_minutes=0,
            out=tmp,
            updates_per_step=args.updates_per_step,
        )
        trainer = Trainer(config, Path(tmp) / "run", progress=False, hooks=hooks)
        compile_s = precompile(trainer)
        start = time.perf_counter()
        trainer.train()
        total_s = time.perf_counter() - start
        ups = update_only(trainer, args.update_only, args.repeat)
    episodes, solves = hooks.episodes, hooks.solves

    learn = [e for e in episodes if e["learning"]]
    if not learn:
        raise SystemExit("no learning episode: --steps must exceed --start-steps")
    random_eps = [e for e in episodes if not e["learning"]]
    # Wall time from the first learning episode's start to the last one's end: includes the
    # loop's bookkeeping between episodes (metrics.csv, progress bar), not the final checkpoint.
    wall = learn[-1]["end"] - learn[0]["start"]
    steps = sum(e["steps"] for e in learn)
    seconds = dict(hooks.seconds)
    seconds["other"] = wall - sum(seconds.get(p, 0.0) for p in PIECES if p != "other")
    summary = {
        "bench": "train_loop",
        "env": config.env,
        "algo": config.algo,
        "preset": config.preset,
        "fixed_horizon": config.uses_fixed_horizon,
        "steps": config.steps,
        "start_steps": config.start_steps,
        "learning_steps": steps,
        "learning_seconds": round(wall, 3),
        "steps_per_s": round(steps / wall, 2),
        "random_phase_steps_per_s": round(
            sum(e["steps"] for e in random_eps) / sum(e["end"] - e["start"] for e in random_eps), 1
        )
        if random_eps
        else None,
        "updates_per_step": config.updates_per_step,
        "update_only_updates_per_s": round(ups, 2),
        "loop_vs_update_only": round(steps * config.updates_per_step / wall / ups, 4),
        "env_plus_reward_share": round((seconds["env"] + seconds["reward"]) / wall, 4),
        "sinkhorn_iterations_mean": round(float(np.mean([i for i, _ in solves if i])), 1)
        if any(i for i, _ in solves)
        else None,
        "sinkhorn_converged": sum(c for _, c in solves),
        "sinkhorn_solves": len(solves),
        "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
        "compile_seconds": round(compile_s, 2),
        "total_seconds": round(total_s, 2),
    }
    pieces = []
    for piece in PIECES:
        s = seconds.get(piece, 0.0)
        pieces.append(
            {
                "bench": "train_piece",
                "preset": config.preset,
                "piece": piece,
                "seconds": round(s, 4),
                "calls": hooks.calls.get(piece),
                "us_per_step": round(1e6 * s / steps, 2),
                "share": round(s / wall, 4),
            }
        )
    return summary, pieces


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", action="store_true", help="one JSON line per figure")
    parser.add_argument("--quick", action="store_true", help="2,000 steps, 1,000 random")
    parser.add_argument("--preset", choices=("fast", "paper"), default="fast")
    parser.add_argument(
        "--algo",
        choices=("oops-td3", "oops-ddpg", "pwil-td3", "gaifo-td3", "opolo", "firl-fkl"),
        default="oops-td3",
        help="the algorithm (the baselines with their authors' settings; --preset is OOPS's)",
    )
    parser.add_argument("--steps", type=int, default=20_000, help="environment steps in all")
    parser.add_argument("--start-steps", type=int, default=10_000, help="random steps first")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--updates-per-step", type=int, default=1, help="update-to-data ratio (paper: 1)"
    )
    parser.add_argument(
        "--update-only", type=int, default=1000, help="updates per timed update-only call"
    )
    parser.add_argument("--repeat", type=int, default=3, help="update-only calls; best is kept")
    args = parser.parse_args()
    if args.quick:
        args.steps, args.start_steps, args.repeat, args.update_only = 2000, 1000, 1, 200
    summary, pieces = run(args)
    meta = {"date": date.today().isoformat(), "machine": machine(jax=jax.__version__)}
    if args.json:
        for row in (summary, *pieces):
            print(json.dumps({**row, **meta}))
        return
    s = summary
    print(f"# {meta['date']}, {meta['machine']}")
    print(
        f"# {s['env']} {s['algo']}, preset {s['preset']}, {s['updates_per_step']} update(s) "
        f"per step: {s['steps']} steps, "
        f"{s['start_steps']} random; figures over the {s['learning_steps']} learning steps "
        f"({s['learning_seconds']:.1f} s; update chunks compiled beforehand in "
        f"{s['compile_seconds']:.1f} s); OPENBLAS_NUM_THREADS={s['openblas_num_threads']}"
    )
    print("| piece | seconds | us/step | share |")
    print("|---|---|---|---|")
    for p in pieces:
        print(
            f"| {p['piece']} | {p['seconds']:.2f} | {p['us_per_step']:.1f} "
            f"| {100 * p['share']:.1f}% |"
        )
    print(
        f"loop: {s['steps_per_s']:.1f} steps/s after the random phase "
        f"(random phase {s['random_phase_steps_per_s']} steps/s); update only: "
        f"{s['update_only_updates_per_s']:.1f} updates/s; loop = "
        f"{100 * s['loop_vs_update_only']:.0f}% of the update-only rate; env + OT reward = "
        f"{100 * s['env_plus_reward_share']:.1f}% of a step (target < 10%)"
    )
    print(
        f"OT reward: {s['sinkhorn_solves']} Sinkhorn solves in the learning phase, "
        f"{s['sinkhorn_converged']} converged, {s['sinkhorn_iterations_mean']} iterations on "
        "average"
    )


if __name__ == "__main__":
    main()
