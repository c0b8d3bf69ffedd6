"""When and how a MinitaurDuck policy loses the duck: where the duck sits on the robot's back.

MinitaurBulletDuckEnv-v0 ends the episode when the duck touches the ground, and its
observations do not include the duck: a policy keeps it only by a gait that does not shake it
off. This script rolls out a run's policy (or an exported expert) deterministically and reports,
per episode, the step at which the duck was lost, the robot's speed, and the duck's offset from
the robot's base (x forward, y left) along the way: the offset wanders as the robot walks, and
the duck falls once it reaches the edge of the back (~0.17-0.24 m).

    python bench/duck.py --expert MinitaurBulletDuckEnv-v0 [--episodes 5] [--json]
    python bench/duck.py RUN_DIR [--best]
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
from ilfo.benchmarking import machine, parse_policy_arguments
from ilfo.envs import make_env
from ilfo.envs.bullet import MINITAUR_DUCK_ENV_ID
from ilfo.experts import load_expert
from ilfo.training import load_run_policy
from ilfo.training.rollout import agent_observation, env_action

HORIZON = 1000


def duck_episode(act: Any, seed: int) -> dict[str, Any]:
    """One deterministic episode of ``act(observation, t) -> action``, to the duck's loss or the
    horizon, with the duck's offset from the base at each step."""
    env = make_env(MINITAUR_DUCK_ENV_ID, True, horizon=HORIZON)
    obs, _ = env.reset(seed=seed)
    inner = env.unwrapped._env  # pybullet_envs' MinitaurBulletDuckEnv
    client = inner._pybullet_client
    offsets, task_return, lost_at = [], 0.0, None
    start_x = float(inner.minitaur.GetBasePosition()[0])
    for t in range(HORIZON):
        obs, reward, _, _, _ = env.step(act(obs, t))
        task_return += float(reward)
        base = np.asarray(inner.minitaur.GetBasePosition())
        duck = np.asarray(client.getBasePositionAndOrientation(inner._duckId)[0])
        offsets.append(duck - base)
        if inner.lost_duck():
            lost_at = t + 1
            break
    end_x = float(inner.minitaur.GetBasePosition()[0])
    env.close()
    offsets = np.asarray(offsets)
    planar = np.linalg.norm(offsets[:, :2], axis=1)
    steps = len(offsets)
    return {
        "seed": seed,
        "lost_duck_at": lost_at,
        "task_score": task_return,  # no reward after the loss: the episode has ended
        "speed": (end_x - start_x) / steps / 0.01,
        "offset_at_100": planar[min(99, steps - 1)].item(),
        "offset_max_before_loss": float(planar[: max(1, steps - 20)].max()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    args = parse_policy_arguments(parser, first_seed=1000)
    if args.expert:
        expert = load_expert(args.expert)
        agent, policy, label = expert.agent, expert.policy, f"expert {args.expert}"
        env_id = expert.config.env
    else:
        run = load_run_policy(Path(args.run_dir), "best" if args.best else "final")
        agent, policy, env_id = run.agent, run.policy, run.config.env
        label = f"{args.run_dir}, {run.source}"
    if env_id != MINITAUR_DUCK_ENV_ID:
        raise SystemExit(f"{label} is a {env_id} policy, not {MINITAUR_DUCK_ENV_ID}")

    def act(obs: np.ndarray, t: int) -> np.ndarray:
        action = agent.functions.act(policy, agent_observation(obs, t, HORIZON, agent.time_feature))
        return env_action(np.asarray(action), agent.functions.max_action)

    rows = [duck_episode(act, args.first_seed + k) for k in range(args.episodes)]
    meta = {"bench": "duck", "date": time.strftime("%Y-%m-%d"), "machine": machine()}
    meta["policy"] = label
    if args.json:
        for row in rows:
            print(json.dumps({**meta, **row}))
        return
    print(f"{label}, {args.episodes} deterministic episodes of {HORIZON} steps")
    print("seed  lost at  score  speed (m/s)  offset at 100  max offset before the loss")
    for r in rows:
        print(
            f"{r['seed']}  {r['lost_duck_at']!s:>7}  {r['task_score']:5.2f}  {r['speed']:11.2f}  "
            f"{r['offset_at_100']:13.3f}  {r['offset_max_before_loss']:.3f}"
        )
    kept = sum(r["lost_duck_at"] is None for r in rows)
    scores = [r["task_score"] for r in rows]
    print(
        f"kept the duck in {kept} of {len(rows)}; "
        f"score {np.mean(scores):.2f} +- {np.std(scores):.2f}"
    )


if __name__ == "__main__":
    main()
