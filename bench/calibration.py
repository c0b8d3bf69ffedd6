"""Calibration of the OOPS reward against the task reward (the paper's calibration plot).

A shipped expert acts with Gaussian noise N(0, l^2) added to its actions (clipped to the action
box), for several l; every episode is a fixed-horizon one, scored both by the task (the paper's
score: rewards of steps where the environment reports a fall are zeroed) and by OOPS against the
expert's first demo (the proxy return, the sum of the OT rewards, and the OT distance). Two
policies without the expert close the table: zero actions and uniformly random actions. A reward
that ranks behaviour like the task does has a high rank correlation between the two returns.

    python bench/calibration.py                        # Hopper-v5, table
    python bench/calibration.py --env Hopper-v5 --episodes 5 --json
    python bench/calibration.py --metric euclidean     # one of the paper's cost ablations
    python bench/calibration.py --env Humanoid-v5 --contact-forces  # gymnasium v5 states
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import date
from pathlib import Path

import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.benchmarking import machine
from ilfo.experiments.calibration import calibrate, pearson, spearman
from ilfo.ot import METRICS
from ilfo.rewards import OOPSConfig
from ilfo.training.config import default_contact_forces

NOISE_LEVELS = (0.0, 0.1, 0.2, 0.3, 0.5, 0.8, 1.2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--env", default="Hopper-v5", help="an env with a shipped expert")
    parser.add_argument(
        "--expert", default=None, help="an expert directory (default: the env's shipped one)"
    )
    parser.add_argument("--episodes", type=int, default=3, help="episodes per policy")
    parser.add_argument(
        "--metric", default="sqrt_euclidean", choices=METRICS, help="OOPS ground cost"
    )
    parser.add_argument(
        "--atoms", default="transitions", choices=("transitions", "states"), help="OOPS atoms"
    )
    parser.add_argument(
        "--contact-forces",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="Ant-v5, Humanoid-v5: reward the states with their contact forces (default: "
        "without, as ilfo train imitates)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON line per policy")
    args = parser.parse_args()
    if args.contact_forces is None:
        args.contact_forces = default_contact_forces(args.env, imitation=True)

    stamp = {"date": date.today().isoformat(), "machine": machine(), "metric": args.metric,
             "atoms": args.atoms, "contact_forces": args.contact_forces}  # fmt: skip
    points = calibrate(
        args.env,
        NOISE_LEVELS,
        args.episodes,
        OOPSConfig(metric=args.metric, atoms=args.atoms),
        expert_directory=args.expert,
        contact_forces=args.contact_forces,
    )
    if not args.json:
        print(
            f"{args.env}, {args.episodes} episodes per row, OOPS ({args.metric}, "
            f"{args.atoms}) against demo 0"
            + ("" if args.contact_forces else ", states without their contact forces")
        )
        print(f"{'policy':>14} {'task score':>11} {'proxy return':>13} {'OT distance':>12}")
    for name in dict.fromkeys(p.policy for p in points):
        group = [p for p in points if p.policy == name]
        score, proxy, distance = (
            float(np.mean([getattr(p, k) for p in group]))
            for k in ("task_score", "proxy_return", "ot_distance")
        )
        if args.json:
            print(json.dumps({"bench": "calibration", "env": args.env, "policy": name,
                              "noise": group[0].noise, "task_score": round(score, 1),
                              "proxy_return": round(proxy, 1), "ot_distance": round(distance, 3),
                              **stamp}))  # fmt: skip
        else:
            print(f"{name:>14} {score:11.1f} {proxy:13.1f} {distance:12.3f}")
    rho, r = spearman(points), pearson(points)
    if args.json:
        summary = {"bench": "calibration_summary", "env": args.env, "spearman": rho, "pearson": r}
        print(json.dumps({**summary, **stamp}))
    else:
        print(f"Task score vs proxy return, per episode: Spearman {rho:.3f}, Pearson {r:.3f}")
        print(stamp["machine"], stamp["date"])


if __name__ == "__main__":
    main()
