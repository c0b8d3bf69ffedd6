"""Where a Hopper or Walker2d policy loses the paper's score: which health condition fails.

The paper's fixed-horizon score zeroes the task reward of every step on which the environment
calls the robot unhealthy (torso too low, torso angle out of range, a state out of range). This
script rolls out a run's policy (or a shipped expert) deterministically and counts, per
episode, the unhealthy steps and which condition made them so, beside the torso angle the
demos hold: a learner can lose much of its score to a lean it never falls from.

    python bench/health.py RUN_DIR [--best] [--episodes 5] [--json]
    python bench/health.py --expert Hopper-v5
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo import demos as demo_io
from ilfo.benchmarking import machine, parse_policy_arguments
from ilfo.envs import HEALTHY_ANGLE_ENVS, episode_scores, make_env
from ilfo.experts import load_expert
from ilfo.training import default_demos_path, load_run_policy, rollout_policy


def health_report(env: Any, observations: np.ndarray) -> dict[str, float]:
    """Counts of unhealthy states by condition, from ``env``'s own health ranges (gymnasium
    v5 Hopper and Walker2d: observation 0 is the torso height, 1 its angle)."""
    z, angle = observations[:, 0], observations[:, 1]
    z_low, z_high = env.unwrapped._healthy_z_range
    a_low, a_high = env.unwrapped._healthy_angle_range
    return {
        "z_out": int(np.sum((z <= z_low) | (z >= z_high))),
        "angle_out": int(np.sum((angle <= a_low) | (angle >= a_high))),
        "angle_mean": float(angle.mean()),
        "angle_min": float(angle.min()),
        "angle_max": float(angle.max()),
        # qpos without x (nq - 1 columns), then qvel: qvel[0], the x velocity, comes next.
        "x_velocity_mean": float(observations[:, env.unwrapped.model.nq - 1].mean()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    args = parse_policy_arguments(parser, first_seed=10_000)

    if args.expert:
        expert = load_expert(args.expert)
        env_id, label = expert.config.env, f"expert {args.expert}"
        rollout = expert.rollout
        own_demos = Path(args.expert) / "demos.npz"
        demo_path = own_demos if own_demos.is_file() else default_demos_path(env_id)
    else:
        run = load_run_policy(Path(args.run_dir), "best" if args.best else "final")
        which = run.source
        if args.best:
            info = json.loads((Path(args.run_dir) / "best_policy.json").read_text())
            which += f" (step {info['step']})"
        env_id, label = run.config.env, f"{args.run_dir}, {which}"
        # The env's own health ranges: the paper's score, whatever the run trained with.
        run_env = make_env(env_id, True, horizon=run.env.horizon)

        def rollout(seed: int):
            return rollout_policy(run_env, run.agent, run.policy, run.env.horizon, seed=seed)

        demo_path = Path(run.config.demos or default_demos_path(env_id))
    if env_id not in HEALTHY_ANGLE_ENVS:
        raise SystemExit(f"{env_id}: only {', '.join(HEALTHY_ANGLE_ENVS)} have these conditions")

    env = make_env(env_id)
    demo = demo_io.load(demo_path).episodes[0].observations
    rows = []
    for k in range(args.episodes):
        r = rollout(args.first_seed + k)
        score, standard = episode_scores(r.rewards, r.env_terminated)
        first = int(np.argmax(r.env_terminated)) if r.env_terminated.any() else None
        rows.append(
            {
                "seed": args.first_seed + k,
                "score": float(score),
                "standard_return": float(standard),
                "unhealthy_steps": int(r.env_terminated.sum()),
                "first_unhealthy_step": first,
                **health_report(env, r.observations[1:]),
            }
        )
    demo_row = health_report(env, demo[1:])
    meta = {
        "bench": "health",
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine(),
        "env": env_id,
        "policy": label,
    }
    if args.json:
        for row in rows:
            print(json.dumps({**meta, **row}))
        print(json.dumps({**meta, "demo": str(demo_path), **demo_row}))
        return
    print(f"{label} ({env_id}), {args.episodes} deterministic fixed-horizon episodes")
    print("seed  score  standard  unhealthy  first  z_out  angle_out  angle mean [min, max]  x-vel")
    for r in rows:
        print(
            f"{r['seed']}  {r['score']:6.0f}  {r['standard_return']:8.0f}  "
            f"{r['unhealthy_steps']:9d}  {r['first_unhealthy_step']!s:>5}  {r['z_out']:5d}  "
            f"{r['angle_out']:9d}  {r['angle_mean']:+.3f} [{r['angle_min']:+.3f}, "
            f"{r['angle_max']:+.3f}]  {r['x_velocity_mean']:.2f}"
        )
    d = demo_row
    print(
        f"demo 0 of {demo_path}: angle mean {d['angle_mean']:+.3f} [{d['angle_min']:+.3f}, "
        f"{d['angle_max']:+.3f}], x-vel {d['x_velocity_mean']:.2f}, "
        f"angle_out {d['angle_out']}, z_out {d['z_out']}"
    )


if __name__ == "__main__":
    main()
