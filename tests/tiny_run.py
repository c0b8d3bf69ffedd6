"""The smallest run the loop's tests train: Hopper-v5 from the shipped scripted demos, 100-step
episodes, 200 random steps, an evaluation and a checkpoint every 200 steps, the fast preset."""

import csv
from pathlib import Path

from ilfo.algos import ALGOS
from ilfo.paths import bundled_demos
from ilfo.training import TrainConfig, Trainer

DEMOS = str(bundled_demos("Hopper-v5-scripted"))

TINY_RUN = {
    "env": "Hopper-v5",
    "demos": DEMOS,
    "horizon": 100,
    "start_steps": 200,
    "eval_every": 200,
    "eval_episodes": 1,
    "checkpoint_every": 200,
    "preset": "fast",
    "replay_capacity": 5000,
}


def metrics_rows(run_dir: Path) -> list[dict[str, str]]:
    """A run's metrics.csv rows without the wall-clock columns, which differ between runs by
    nature: what two runs that should be the same must agree on."""
    with (run_dir / "metrics.csv").open() as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        row.pop("wall_time")
        row.pop("steps_per_s")
    return rows


def train_tiny(tmp_path: Path, name: str, **overrides) -> Path:
    """Train ``TINY_RUN`` for 600 steps (with ``overrides``) in ``tmp_path / name``."""
    settings = {**TINY_RUN, "steps": 600, **overrides}
    if not ALGOS[settings.get("algo", "oops-td3")].imitation:
        settings.pop("demos")  # the task reward: demos are refused
    config = TrainConfig(**settings)
    return Trainer(config, tmp_path / name, progress=False).train()
