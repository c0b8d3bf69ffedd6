"""Offline labelling speed (`ilfo label`): a D4RL-style dataset of 1,000 Hopper-v5 episodes of
1,000 steps (1M transitions) labelled against 1 (or more) shipped expert demos.

The dataset's episodes are the shipped expert's 10 demos with Gaussian noise of several scales
added to the observations (so that episodes differ from the demo and from each other, as an
offline dataset's do, and Sinkhorn works as hard as on real data); written once as a D4RL HDF5
file in a temporary directory, then labelled with 1 and 2 workers.

    python bench/label.py                       # 1,000 episodes, 1 demo, workers 1 and 2
    python bench/label.py --episodes 200 --num-demos 10 --json
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot`.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo import demos
from ilfo.benchmarking import print_rows
from ilfo.experts import expert_dir
from ilfo.labelling import LabelConfig, label_dataset


def write_dataset(path: Path, episodes: int, seed: int = 0) -> int:
    source = demos.load(expert_dir("Hopper-v5") / "demos.npz").episodes
    rng = np.random.default_rng(seed)
    obs, nxt, acts, terminals = [], [], [], []
    for k in range(episodes):
        e = source[k % len(source)]
        noisy = e.observations + rng.normal(
            0.0, rng.choice([0.01, 0.05, 0.2]), e.observations.shape
        )
        obs.append(noisy[:-1])
        nxt.append(noisy[1:])
        acts.append(e.actions)
        end = np.zeros(len(e.actions), bool)
        end[-1] = True
        terminals.append(end)
    with h5py.File(path, "w") as f:
        f.create_dataset("observations", data=np.concatenate(obs).astype(np.float32))
        f.create_dataset("next_observations", data=np.concatenate(nxt).astype(np.float32))
        f.create_dataset("actions", data=np.concatenate(acts))
        f.create_dataset("rewards", data=np.zeros(sum(len(a) for a in acts), np.float32))
        f.create_dataset("timeouts", data=np.concatenate(terminals))
    return sum(len(a) for a in acts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--num-demos", type=int, default=1)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="ilfo-bench-label-"))
    try:
        data = tmp / "data.hdf5"
        transitions = write_dataset(data, args.episodes)
        rows = []
        for workers in args.workers:
            out = tmp / f"out-{workers}.hdf5"
            start = time.perf_counter()
            summary = label_dataset(
                data,
                expert_dir("Hopper-v5") / "demos.npz",
                out,
                LabelConfig(),
                num_demos=args.num_demos,
                env_id="Hopper-v5",
                workers=workers,
            )
            rows.append(
                {
                    "episodes": summary.episodes,
                    "transitions": transitions,
                    "num_demos": args.num_demos,
                    "workers": workers,
                    "label_s": summary.seconds,
                    "total_s": time.perf_counter() - start,
                    "ms_per_episode_solve": 1000
                    * summary.seconds
                    * workers
                    / (summary.episodes * args.num_demos),
                }
            )
            out.unlink()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    columns = {
        "episodes": "{episodes}",
        "transitions": "{transitions:,}",
        "demos": "{num_demos}",
        "workers": "{workers}",
        "labelling s": "{label_s:.1f}",
        "with reading and writing s": "{total_s:.1f}",
        "ms per solve and core": "{ms_per_episode_solve:.1f}",
    }
    print_rows(rows, columns, args.json)


if __name__ == "__main__":
    main()
