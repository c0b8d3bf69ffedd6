"""Calibration of the OOPS reward against the task reward (the paper's calibration figure).

A shipped expert acts with Gaussian noise N(0, l^2) added to its actions (clipped to the action
box), for several l (the paper: l in [0, 1.5], 5 trajectories each); every episode is a
fixed-horizon one, scored both by the task (the paper's score: rewards of steps where the
environment reports a fall are zeroed) and by OOPS against the expert's first demo (the proxy
return, the sum of the OT rewards, and the OT distance). Two policies without the expert close
the set: zero actions and uniformly random actions. A reward that ranks behaviour as the task
does has a high rank correlation between the two returns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from ilfo.rewards import OOPSConfig

if TYPE_CHECKING:
    from gymnasium.spaces import Box

PAPER_NOISE_LEVELS: tuple[float, ...] = tuple(round(0.1 * k, 1) for k in range(16))
"""The paper's range of l, in steps of 0.1."""


@dataclass(frozen=True)
class CalibrationPoint:
    """One episode of one policy."""

    policy: str
    """``expert + N(0, l^2)``, ``zero`` or ``random``."""
    noise: float | None
    episode: int
    task_score: float
    proxy_return: float
    ot_distance: float


def calibrate(
    env_id: str,
    noise_levels: Sequence[float],
    episodes: int = 5,
    oops: OOPSConfig | None = None,
    expert_directory: str | Path | None = None,
    horizon: int | None = None,
    contact_forces: bool | None = None,
) -> list[CalibrationPoint]:
    """Every (policy, episode) of the calibration of ``env_id``'s expert (see the module);
    ``horizon`` shortens the episodes (None: the expert's). ``contact_forces`` (Ant-v5,
    Humanoid-v5): whether OOPS rewards the states with their contact forces (the expert acts
    on what it observes of them, ``ExpertPolicy.observe``); None: as ``ilfo train`` imitates
    (``default_contact_forces``: without them)."""
    from ilfo import demos
    from ilfo.envs import drop_contact_forces, episode_scores, make_env
    from ilfo.experts import expert_dir, load_expert
    from ilfo.rewards import OOPS
    from ilfo.training.config import default_contact_forces

    directory = Path(expert_directory) if expert_directory else expert_dir(env_id)
    expert = load_expert(directory)
    if expert.config.env != env_id:
        raise ValueError(f"{directory} is an expert for {expert.config.env}, not {env_id}")
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    demo = demos.load(directory / "demos.npz").episodes[0].observations

    # The env and the demos have every column; the expert acts on what it observes of them.
    if contact_forces is None:
        contact_forces = default_contact_forces(env_id, imitation=True)

    def reward_view(observations: np.ndarray) -> np.ndarray:
        return observations if contact_forces else drop_contact_forces(observations, env_id)

    rewarder = OOPS([reward_view(demo)], oops or OOPSConfig())
    steps = horizon or expert.horizon
    env = make_env(env_id, fixed_horizon=True, horizon=steps)
    actions = cast("Box", env.action_space)  # make_env's environments act in a Box
    low, high = actions.low, actions.high
    act_expert = expert.agent.functions.act

    def act(kind: float | str, obs: np.ndarray, t: int, rng: np.random.Generator) -> np.ndarray:
        if kind == "zero":
            return np.zeros_like(low)
        if kind == "random":
            return rng.uniform(low, high)
        agent_obs = expert.observe(obs)
        if expert.agent.time_feature:  # the expert's own clock: its horizon, not ``steps``
            agent_obs = np.append(agent_obs, (expert.horizon - t) / expert.horizon)
        action = np.asarray(act_expert(expert.policy, agent_obs.astype(np.float32)))
        return np.clip(action + rng.normal(0.0, float(kind), action.shape), low, high)

    points = []
    try:
        kinds: tuple[float | str, ...] = (*noise_levels, "zero", "random")
        for kind in kinds:
            rng = np.random.default_rng(0)
            for k in range(episodes):
                obs, _ = env.reset(seed=100 + k)
                observations, rewards, fell = [obs], [], []
                for t in range(steps):
                    obs, reward, _, _, info = env.step(act(kind, obs, t, rng))
                    observations.append(obs)
                    rewards.append(reward)
                    fell.append(info["env_terminated"])
                score = episode_scores(np.array(rewards), np.array(fell))[0]
                out = rewarder(reward_view(np.asarray(observations)))
                name = f"expert + N(0, {kind}^2)" if not isinstance(kind, str) else kind
                noise = None if isinstance(kind, str) else float(kind)
                points.append(
                    CalibrationPoint(
                        name, noise, k, float(score), float(out.rewards.sum()), out.distance
                    )
                )
    finally:
        env.close()
    return points


def _score_proxy_arrays(points: Sequence[CalibrationPoint]) -> tuple[np.ndarray, np.ndarray] | None:
    """The two returns as arrays, or None where a correlation is undefined: fewer than two
    episodes, or either return constant (e.g. a smoke horizon too short to score)."""
    scores = np.array([p.task_score for p in points], dtype=np.float64)
    proxies = np.array([p.proxy_return for p in points], dtype=np.float64)
    if len(points) < 2 or np.ptp(scores) == 0 or np.ptp(proxies) == 0:
        return None
    return scores, proxies


def spearman(points: Sequence[CalibrationPoint]) -> float:
    """Rank correlation of task score and proxy return over all episodes; NaN, without a
    warning, where it is undefined (fewer than two episodes, or a constant return)."""
    from scipy.stats import spearmanr

    arrays = _score_proxy_arrays(points)
    if arrays is None:
        return float("nan")
    return float(spearmanr(*arrays).statistic)


def pearson(points: Sequence[CalibrationPoint]) -> float:
    """Linear correlation of task score and proxy return over all episodes: what the paper's
    scatter plots show. Spearman's ranks are pulled down where many poor policies tie on the
    floor of both returns (their order there is noise); Pearson's r weighs them by distance.
    NaN, without a warning, where it is undefined, as ``spearman``."""
    arrays = _score_proxy_arrays(points)
    if arrays is None:
        return float("nan")
    return float(np.corrcoef(*arrays)[0, 1])


def write_calibration(results: dict[str, list[CalibrationPoint]], out: Path) -> list[Path]:
    """``calibration.csv`` (every episode), ``calibration.md`` (per env: the rank correlation,
    and the means per policy) and ``calibration_<env>.png`` (proxy return against task score)."""
    import csv
    import dataclasses

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ilfo.experiments.report_figures import finish_figure

    out.mkdir(parents=True, exist_ok=True)
    written = []
    csv_path = out / "calibration.csv"
    with csv_path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["env", *(f.name for f in dataclasses.fields(CalibrationPoint))])
        for env, points in results.items():
            for p in points:
                writer.writerow([env, *dataclasses.astuple(p)])
    written.append(csv_path)
    lines = [
        "# Calibration: the proxy (OOPS) return against the task score",
        "",
        "The expert with Gaussian action noise N(0, l^2), zero and random actions; "
        "fixed-horizon episodes; OOPS against the expert's first demo. Spearman's rank "
        "correlation and Pearson's r over all episodes (the paper: strong correlation in every "
        "environment); the many poor policies that tie near the floor of both returns pull "
        "the ranks down more than r. "
        "Ant-v5 and Humanoid-v5: OOPS scores the states without their contact forces, as "
        "imitation observes them by default (the expert acts on the columns it was trained "
        "on, with or without them).",
        "",
    ]
    for env, points in results.items():
        lines += [
            f"## {env}: Spearman {spearman(points):.3f}, Pearson {pearson(points):.3f}",
            "",
            "| policy | episodes | task score | proxy return | OT distance |",
            "|---|---|---|---|---|",
        ]
        for name in dict.fromkeys(p.policy for p in points):
            group = [p for p in points if p.policy == name]
            means = [
                np.mean([getattr(p, k) for p in group])
                for k in ("task_score", "proxy_return", "ot_distance")
            ]
            lines.append(
                f"| {name} | {len(group)} | {means[0]:.1f} | {means[1]:.1f} | {means[2]:.3f} |"
            )
        lines.append("")
        fig, ax = plt.subplots(figsize=(5, 4))
        noisy = [p for p in points if p.noise is not None]
        scatter = ax.scatter(
            [p.task_score for p in noisy],
            [p.proxy_return for p in noisy],
            c=cast(list[float], [p.noise for p in noisy]),  # noisy: the points with a noise
            cmap="viridis",
        )
        fig.colorbar(scatter, ax=ax, label="action noise l")
        for name, marker in (("zero", "x"), ("random", "+")):
            group = [p for p in points if p.policy == name]
            ax.scatter(
                [p.task_score for p in group],
                [p.proxy_return for p in group],
                marker=marker,
                c="k",
                label=name,
            )
        title = f"{env}: Spearman {spearman(points):.2f}, Pearson {pearson(points):.2f}"
        path = out / f"calibration_{env}.png"
        xlabel, ylabel = "task score (falls zeroed)", "proxy return (sum of OOPS rewards)"
        written.append(finish_figure(fig, ax, title, xlabel, ylabel, path))
    md_path = out / "calibration.md"
    md_path.write_text("\n".join(lines), encoding="utf-8")
    return [md_path, *written]
