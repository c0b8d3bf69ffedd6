"""OOPS in other people's RL code: Stable-Baselines3's SAC and sbx's SAC with ilfo's
``OTReplayBuffer``, beside ilfo's own oops-sac, on Hopper-v5 from the shipped expert's first demo,
the same number of steps each: steps per second and the final score.

Each learns with the paper's protocol (fixed 1,000-step episodes, the time feature; the reward
sees the env's own columns), SAC with Haarnoja et al.'s settings (256-256, lr 3e-4, batch 256,
automatic entropy; the first 10,000 steps random), and ends with 10 deterministic
fixed-horizon episodes scored as ilfo scores them (rewards of steps reported as a fall count 0),
divided by the demo's return.

    python bench/integrations.py --steps 50000                  # ~10-20 min per library here
    python bench/integrations.py --libraries sb3 --steps 20000 --json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.benchmarking import machine
from ilfo.envs import TimeFeature, episode_scores, make_env
from ilfo.rewards import OOPS
from ilfo.training import TrainConfig, Trainer, load_demo_set

ENV = "Hopper-v5"
START = 10_000


def score(predict, demo_return: float, episodes: int = 10) -> float:
    """Mean fixed-horizon score of ``predict(obs) -> action`` over seeded episodes, normalised."""
    scores = []
    for k in range(episodes):
        env = TimeFeature(make_env(ENV, fixed_horizon=True, seed=1000 + k))
        obs, _ = env.reset(seed=1000 + k)
        rewards, fell = [], []
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(predict(obs))
            rewards.append(reward)
            fell.append(info["env_terminated"])
            done = terminated or truncated
        scores.append(episode_scores(np.array(rewards), np.array(fell))[0])
        env.close()
    return float(np.mean(scores)) / demo_return


def run_library(library: str, steps: int, seed: int) -> dict[str, float | str]:
    config = TrainConfig(env=ENV, algo="oops-sac", steps=steps, start_steps=START, seed=seed)
    probe = make_env(ENV, fixed_horizon=True)
    demos = load_demo_set(config, probe.observation_space.shape[0])
    obs_dim = probe.observation_space.shape[0]
    start = time.perf_counter()
    if library == "ilfo":
        out = Path(tempfile.mkdtemp(prefix="ilfo-bench-integrations-"))
        trainer = Trainer(
            dataclasses.replace(config, eval_every=steps, out=str(out)),
            out / "run",
            progress=False,
        )
        trainer.train()
        wall = time.perf_counter() - start
        final = trainer.last_eval["eval_score_norm"]
    else:
        from ilfo.integrations.sb3 import OTReplayBuffer

        if library == "sbx":
            from sbx import SAC
        else:
            from stable_baselines3 import SAC
        env = TimeFeature(make_env(ENV, fixed_horizon=True, seed=seed))
        model = SAC(
            "MlpPolicy",
            env,
            learning_starts=START,
            replay_buffer_class=OTReplayBuffer,
            replay_buffer_kwargs={
                "reward": OOPS(demos.observations),
                "observation_columns": obs_dim,
            },
            seed=seed,
            **({"device": "cpu"} if library == "sb3" else {}),
        )
        model.learn(total_timesteps=steps)
        wall = time.perf_counter() - start
        final = score(lambda o: model.predict(o, deterministic=True)[0], demos.mean_return)
    return {
        "library": library,
        "steps": steps,
        "wall_s": wall,
        "steps_per_s": steps / wall,
        "score_norm": final,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=50_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--libraries", nargs="+", default=["ilfo", "sb3", "sbx"], choices=["ilfo", "sb3", "sbx"]
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = [run_library(name, args.steps, args.seed) for name in args.libraries]
    if args.json:
        for row in rows:
            print(json.dumps({**row, "date": date.today().isoformat(), "machine": machine()}))
        return
    print(f"{date.today().isoformat()}, {machine()}; {ENV}, 1 demo, seed {args.seed}")
    print("| library | steps | wall s | steps/s (whole run) | final score / demo |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['library']} | {r['steps']:,} | {r['wall_s']:.0f} | {r['steps_per_s']:.0f} | "
            f"{r['score_norm']:.2f} |"
        )


if __name__ == "__main__":
    main()
