"""Why doesn't my imitation learn? One run's policy against the demos it imitates
(``ilfo diagnose``; docs/experiments.md).

The run's policy acts in deterministic fixed-horizon episodes on the run's evaluation seeds
(what ``ilfo eval`` rolls out) and OOPS compares each with the demos: the run's own OOPS config
for an OOPS run, the paper's for another imitation run (the distance its evaluations log); with
several demos, each episode with the nearest (the run's ``random`` draw made deterministic) or
with all pooled where the run pooled them. ``diagnose_run`` gathers four views, which
``write_report`` writes: each state dimension's share of the transported cost
(``cost_by_column``: every pair's P_ij C_ij split among the standardised atoms' columns in
proportion to (x_ik - y_jk)^2 / |x_i - y_j|^2, so that the shares sum to 1; a state's two
copies in (s_t, s_t+1) atoms summed), the proxy reward beside the task reward per step, the
learner's distance among noisy copies of the demonstrator (``noisy_demo_copies``; the shipped
expert with action noise, ``experiments.calibration``, where the demos are its), and the
learner's and the demo's states in the dimensions that cost most.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilfo.rewards import OOPS, OOPSConfig

if TYPE_CHECKING:
    from ilfo.experiments.calibration import CalibrationPoint
    from ilfo.training import TrainConfig

DEMO_NOISE_SCALES: tuple[float, ...] = (0.0, 0.01, 0.03, 0.1, 0.3, 1.0)
"""sigma of the noisy copies of the demo, in standardised units (OOPS's scale: 3 std)."""
EXPERT_NOISE_LEVELS: tuple[float, ...] = (0.0, 0.1, 0.3, 0.5, 1.0)
"""The action noise of the shipped expert's episodes (one each, as the calibration's)."""
TABLE_ROWS, GRID_DIMENSIONS = 10, 6  # dimensions in the report's table, in its trajectory grid

_JOINTS = {  # gymnasium's documented order of the joints' angles, then of their velocities
    "Hopper-v5": "thigh, leg, foot",
    "Walker2d-v5": "right thigh, right leg, right foot, left thigh, left leg, left foot",
    "HalfCheetah-v5": "back thigh, back shin, back foot, front thigh, front shin, front foot",
}


def state_names(env_id: str, obs_dim: int) -> list[str]:
    """``s[k]`` for each observation column, with its name where ilfo knows it (Hopper,
    Walker2d and HalfCheetah v5, in gymnasium's documented order)."""
    joints = _JOINTS[env_id].split(", ") if env_id in _JOINTS else []
    named = ["torso z", "torso angle", *(f"{j} angle" for j in joints)]
    named += ["torso x velocity", "torso z velocity", "torso angular velocity"]
    named += [f"{j} angular velocity" for j in joints]
    if not joints or len(named) != obs_dim:
        return [f"s[{k}]" for k in range(obs_dim)]
    return [f"s[{k}] {name}" for k, name in enumerate(named)]


@dataclass(frozen=True)
class EpisodeDiagnosis:
    """One learner episode (observations (T + 1, obs_dim), task rewards (T,) where known)
    against the demos."""

    observations: np.ndarray
    proxy_rewards: np.ndarray
    """(T,): OOPS's rewards of the episode."""
    task_rewards: np.ndarray | None
    distance: float
    """<C, P>: OOPS's OT distance."""
    demo_index: int | None
    """The demo it was compared with (None: all pooled)."""
    column_costs: np.ndarray
    """(atom width,): the part of <C, P> each atom column carries (``cost_by_column``)."""
    converged: bool


@dataclass(frozen=True)
class Diagnosis:
    """Learner episodes against demos, as OOPS with ``config`` sees them."""

    episodes: tuple[EpisodeDiagnosis, ...]
    demos: tuple[np.ndarray, ...]
    config: OOPSConfig
    names: tuple[str, ...]
    """Of the state columns (``time index`` last where ``config.time_index``)."""

    @property
    def shares(self) -> np.ndarray:
        """Each state dimension's share of the transported cost of all episodes together
        (the module's decomposition): non-negative, summing to 1 (all 0 where nothing was
        transported at a cost)."""
        columns = np.sum([e.column_costs for e in self.episodes], axis=0)
        if self.config.atoms == "transitions":  # (s_t, s_t+1): a dimension's two copies
            columns = columns.reshape(2, -1).sum(axis=0)
        total = columns.sum()
        return columns / total if total > 0 else np.zeros_like(columns)

    @property
    def distance(self) -> float:
        """The episodes' mean OT distance."""
        return float(np.mean([e.distance for e in self.episodes]))

    def top(self, k: int) -> list[int]:
        """The ``k`` state dimensions of largest share, largest first."""
        return [int(i) for i in np.argsort(-self.shares, kind="stable")[:k]]


def diagnosis_config(config: OOPSConfig) -> OOPSConfig:
    """``config`` with its demo drawn deterministically: ``random`` becomes ``nearest``."""
    if config.demo_selection == "random":
        return dataclasses.replace(config, demo_selection="nearest")
    return config


def cost_by_column(learner: np.ndarray, expert: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The part of sum_ij W_ij (``weights`` (n, m): each pair's transported cost P_ij C_ij)
    that each column k of the atoms carries: W_ij split among the columns in proportion to
    (x_ik - y_jk)^2 / |x_i - y_j|^2. Sums to sum_ij W_ij over the pairs at a distance (a pair at
    distance 0 has nothing to split, and no cost under OOPS's metrics)."""
    columns = range(learner.shape[1])
    squared = sum((learner[:, k, None] - expert[None, :, k]) ** 2 for k in columns)
    ratio = np.divide(weights, squared, out=np.zeros(weights.shape), where=squared > 0)
    return np.array(
        [np.sum(ratio * (learner[:, k, None] - expert[None, :, k]) ** 2) for k in columns]
    )


def diagnose_episode(
    rewarder: OOPS, observations: np.ndarray, task_rewards: np.ndarray | None = None
) -> EpisodeDiagnosis:
    """One episode (T + 1, obs_dim) against ``rewarder``'s demos: its rewards, its distance and
    where that distance goes."""
    out = rewarder(observations)
    learner = rewarder.atoms(observations)
    demo = -1 if out.demo_index is None else out.demo_index
    expert = np.concatenate(rewarder.expert_atoms) if demo == -1 else rewarder.expert_atoms[demo]
    weights = np.asarray(out.coupling.plan, np.float64) * rewarder.cost(learner, demo)
    costs, task = cost_by_column(learner, expert, weights), task_rewards
    task = None if task is None else np.asarray(task, np.float64)
    observations = np.asarray(observations, np.float64)
    return EpisodeDiagnosis(
        observations, out.rewards, task, out.distance, out.demo_index, costs, out.coupling.converged
    )


def diagnose_episodes(
    episodes: Sequence[np.ndarray],
    demos: Sequence[np.ndarray],
    config: OOPSConfig | None = None,
    task_rewards: Sequence[np.ndarray] | None = None,
    names: Sequence[str] | None = None,
) -> Diagnosis:
    """Learner ``episodes`` (each (T + 1, obs_dim)) against ``demos`` with OOPS (``config``:
    the paper's if None; its ``random`` demo draw made ``nearest``). ``names``: of the
    observation columns (default ``s[k]``)."""
    config = diagnosis_config(config or OOPSConfig())
    rewarder = OOPS(demos, config)
    tasks = [None] * len(episodes) if task_rewards is None else list(task_rewards)
    diagnosed = tuple(
        diagnose_episode(rewarder, obs, task) for obs, task in zip(episodes, tasks, strict=True)
    )
    names = list(names or [f"s[{k}]" for k in range(rewarder.obs_dim)])
    if len(names) != rewarder.obs_dim:
        raise ValueError(f"{len(names)} names for {rewarder.obs_dim} observation columns")
    names += ["time index"] * config.time_index
    demos = tuple(np.asarray(d, np.float64) for d in demos)
    return Diagnosis(diagnosed, demos, config, tuple(names))


@dataclass(frozen=True)
class NoisyCopy:
    """A copy of the demo's first T steps with Gaussian noise, scored by OOPS."""

    sigma: float
    distance: float
    proxy_return: float


def noisy_demo_copies(
    rewarder: OOPS, demo: np.ndarray, steps: int, scales: Sequence[float] = DEMO_NOISE_SCALES
) -> list[NoisyCopy]:
    """``demo``'s first ``steps`` transitions (all of them, where it has fewer) with noise
    N(0, sigma^2) added in each standardised dimension (sigma times the standardiser's scale in
    the raw ones), for each sigma of ``scales``, scored by ``rewarder``; seeded, the same at
    every call."""
    rng = np.random.default_rng(0)
    base = np.asarray(demo[: steps + 1], np.float64)
    copies = []
    for sigma in scales:
        out = rewarder(base + rng.normal(0.0, sigma, base.shape) * rewarder.standardizer.scale)
        copies.append(NoisyCopy(float(sigma), float(out.distance), float(out.rewards.sum())))
    return copies


def expert_calibration(
    config: TrainConfig, demo_file: Path, num_demos: int, horizon: int, oops: OOPSConfig
) -> tuple[list[CalibrationPoint], str | None]:
    """The shipped expert of the run's env with action noise (``EXPERT_NOISE_LEVELS``), zero
    and random actions, one ``horizon``-step episode each, scored by OOPS against its first
    demo (``experiments.calibration.calibrate``); or no points and a one-line note of why not,
    where the diagnosis does not compare with that demo alone."""
    from ilfo.experts import DEMOS_FILE, EXPERT_FILE, expert_dir
    from ilfo.files import file_sha256

    env, directory = config.env, expert_dir(config.env)
    if not (directory / EXPERT_FILE).is_file() or not (directory / DEMOS_FILE).is_file():
        return [], f"skipped: {env} has no shipped expert to add action noise to."
    if num_demos != 1 or file_sha256(directory / DEMOS_FILE) != file_sha256(demo_file):
        return [], (
            f"skipped: it is scored against the shipped {env} expert's first demo, and this "
            f"diagnosis compares with {num_demos} demo(s) of {demo_file}."
        )
    from ilfo.experiments.calibration import calibrate

    cf = config.observes_contact_forces
    try:
        points = calibrate(env, EXPERT_NOISE_LEVELS, 1, oops, horizon=horizon, contact_forces=cf)
    except ImportError as err:  # an env's optional dependency (PyBullet)
        return [], f"skipped: {err}"
    return points, None


@dataclass(frozen=True)
class RunDiagnosis:
    """``diagnose_run``'s findings, what ``write_report`` writes."""

    run_dir: Path
    config: TrainConfig
    policy: str  # the policy file (RunPolicy.source)
    seeds: list[int]
    scores: np.ndarray  # the paper's fixed-horizon score of each episode (falls zeroed)
    returns: np.ndarray
    demo_file: Path
    demo_return: float  # the demos' mean task score (NaN: not recorded)
    diagnosis: Diagnosis
    noisy: list[NoisyCopy]
    expert: list[CalibrationPoint]
    expert_note: str | None
    reward_note: str | None  # where the run's reward is not OOPS: what is measured instead


def diagnose_run(
    run_dir: str | Path, demos: str | Path | None = None, episodes: int = 1, best: bool = False
) -> RunDiagnosis:
    """Diagnose a run's final policy (``best``: its best) in ``episodes`` deterministic
    episodes against the demos it imitates (``demos``: a demo file's instead, its first
    ``num_demos`` episodes as the run took them). Clear errors for a directory that is not a
    run, a run without demos, a missing policy, demos of another width."""
    from ilfo.envs import episode_scores
    from ilfo.training import load_run_policy, read_run_config, rollout_policy
    from ilfo.training.config import check_eval_episodes, config_from_dict
    from ilfo.training.rollout import evaluation_seeds

    run_dir = Path(run_dir)
    check_eval_episodes(episodes, "--episodes")
    config = config_from_dict(read_run_config(run_dir), run_dir / "config.json")
    if not config.imitation:
        raise ValueError(
            f"{run_dir} is a {config.algo} run on the task reward, without demos: diagnose "
            "needs an imitation run (one that learns from demos, e.g. --algo oops-td3)"
        )
    run = load_run_policy(run_dir, "best" if best else "final")
    observations, demo_file, demo_return = _demos(run_dir, config, run.env.obs_dim, demos)
    oops, reward_note = _reward_config(config)
    seeds, horizon = evaluation_seeds(config.seed, episodes), run.env.horizon
    env = run.eval_env()
    try:
        rollouts = [rollout_policy(env, run.agent, run.policy, horizon, seed) for seed in seeds]
    finally:
        env.close()
    learners, tasks = [r.observations for r in rollouts], [r.rewards for r in rollouts]
    names = state_names(config.env, run.env.obs_dim)
    diagnosis = diagnose_episodes(learners, observations, oops, tasks, names)
    copied = observations[diagnosis.episodes[0].demo_index or 0]
    copies = noisy_demo_copies(OOPS(observations, diagnosis.config), copied, horizon)
    expert = expert_calibration(config, demo_file, len(observations), horizon, diagnosis.config)
    scored = np.array([episode_scores(r.rewards, r.env_terminated) for r in rollouts])
    return RunDiagnosis(
        run_dir, config, run.source, seeds, scored[:, 0], scored[:, 1], demo_file,
        demo_return, diagnosis, copies, *expert, reward_note,
    )  # fmt: skip


def _demos(
    run_dir: Path, config: TrainConfig, obs_dim: int, demos: str | Path | None
) -> tuple[list[np.ndarray], Path, float]:
    """The demos to compare with (the run's, or the first ``num_demos`` of ``demos``), their
    file and their mean task score."""
    from ilfo.envs import match_observation_width

    if demos is None:
        from ilfo.training import load_demo_set
        from ilfo.training.run_dir import read_demos_record

        demo_set = load_demo_set(config, obs_dim)
        assert demo_set.source is not None  # an imitation run's
        record = read_demos_record(run_dir)
        if record is not None and record.get("sha256") != demo_set.source.sha256:
            warnings.warn(
                f"{demo_set.source.path} has changed since the run started on it (its sha256 "
                "is not demos.json's): the diagnosis compares with the file as it is now",
                stacklevel=2,
            )
        return demo_set.observations, Path(demo_set.source.path), demo_set.mean_return
    from ilfo.demos import load_any

    episodes = load_any(demos, env_id=config.env).episodes[: config.num_demos]
    observations = [np.asarray(e.observations) for e in episodes]
    if not config.observes_contact_forces:  # as load_demo_set fits full-width demos
        observations = [match_observation_width(o, config.env, obs_dim) for o in observations]
    if observations[0].shape[1] != obs_dim:
        raise ValueError(
            f"--demos {demos}: observations of width {observations[0].shape[1]}, the run's "
            f"{config.env} observes {obs_dim}"
        )
    returns = [e.task_score for e in episodes if e.task_score is not None]
    return observations, Path(demos), float(np.mean(returns)) if returns else math.nan


def _reward_config(config: TrainConfig) -> tuple[OOPSConfig, str | None]:
    """The OOPS config to diagnose with, and a note where it is not the run's reward."""
    if config.recipe.reward == "oops":
        return config.part_config("oops"), None
    return OOPSConfig(), (
        f"The run's reward is {config.recipe.reward} ({config.algo}): this diagnosis measures "
        "with OOPS at the paper's settings (the OT distance its evaluations log), so its proxy "
        "rewards are OOPS's, not the ones the run learned from."
    )


REPORT_FILE = "diagnosis.md"


def write_report(result: RunDiagnosis, out: str | Path) -> list[Path]:
    """``diagnosis.md`` and its figures (``shares.png``, ``rewards.png``, ``calibration.png``,
    ``trajectories.png``) in ``out``; their paths, the markdown's first."""
    import matplotlib

    matplotlib.use("Agg")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plots = (_plot_shares, _plot_rewards, _plot_calibration, _plot_grid)
    figures = [plot(result, out) for plot in plots]
    lines = [*_overview(result), *_shares_section(result), *_rewards_section(result)]
    lines += [*_calibration_section(result), "## 4. The learner's and the demo's states", ""]
    lines += [
        f"The {GRID_DIMENSIONS} dimensions of largest share, raw, along each episode's steps: the "
        "learner's, the demo(s) compared with.\n\n![trajectories](trajectories.png)"
    ]
    path = out / REPORT_FILE
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [path, *figures]


def summary_lines(result: RunDiagnosis, report: Path) -> list[str]:
    """What ``ilfo diagnose`` prints: the run, the policy, its score and distance, the top
    three dimensions, where the report is."""
    d, config = result.diagnosis, result.config
    top = ", ".join(f"{d.names[k]} {d.shares[k]:.1%}" for k in d.top(3))
    steps = len(d.episodes[0].proxy_rewards)
    return [
        f"run: {result.run_dir} ({config.env}, {config.algo}, seed {config.seed})",
        f"policy: {result.policy}, {len(d.episodes)} deterministic episode(s) of {steps} steps",
        f"score: {_score(result)}; return {np.mean(result.returns):.1f}",
        f"OT distance: {d.distance:.4f}, {_placement(result)}",
        f"top dimensions (share of the transported cost): {top}",
        f"report: {report}",
    ]


def _score(result: RunDiagnosis) -> str:
    score, demos = np.mean(result.scores), result.demo_return
    normalised = "" if math.isnan(demos) else f", {score / demos:.2f} of the demos' {demos:.1f}"
    return f"{score:.1f} (falls zeroed){normalised}"


def _placement(result: RunDiagnosis) -> str:
    """Where the learner's distance lies among the noisy copies of the demo."""
    distance, copies = result.diagnosis.distance, sorted(result.noisy, key=lambda c: c.distance)
    steps = len(result.diagnosis.episodes[0].proxy_rewards)
    floor = f"the demo's own first {steps} steps: {_floor(result).distance:.4f}"
    if distance <= copies[0].distance:
        return f"at or below the demo's noisy copies ({floor})"
    for lower, upper in itertools.pairwise(copies):
        if distance <= upper.distance:
            return f"as the demo with noise sigma {lower.sigma:g} to {upper.sigma:g} ({floor})"
    return f"beyond the demo with noise sigma {copies[-1].sigma:g} ({floor})"


def _floor(result: RunDiagnosis) -> NoisyCopy:
    """The copy of the demo with the least noise (none, with the default scales)."""
    return min(result.noisy, key=lambda c: c.sigma)


def _compared_demos(d: Diagnosis) -> list[np.ndarray]:
    """The demos the episodes were compared with (all, where pooled)."""
    used = sorted({e.demo_index for e in d.episodes if e.demo_index is not None})
    return list(d.demos) if not used else [d.demos[i] for i in used]


def _overview(result: RunDiagnosis) -> list[str]:
    d, config, cfg = result.diagnosis, result.config, result.diagnosis.config
    how = {"pooled": "all pooled", "nearest": "each episode with its nearest"}[cfg.demo_selection]
    how = "one demo" if len(d.demos) == 1 else f"{len(d.demos)} demos, {how}"
    extras = ", time index" * cfg.time_index + ", time-weighted cost" * cfg.time_weighted_cost
    lines = [
        f"# Diagnosis of `{result.run_dir}`",
        "",
        f"{config.env}, {config.algo}, seed {config.seed}; policy `{result.policy}`, "
        f"{len(d.episodes)} deterministic fixed-horizon episode(s) of "
        f"{len(d.episodes[0].proxy_rewards)} steps on the run's evaluation seeds. Demos: "
        f"`{result.demo_file}` ({how}). OOPS: {cfg.atoms} atoms, {cfg.metric} cost, "
        f"{cfg.solver} (reg {cfg.reg:g}){extras}.",
        "",
        *([result.reward_note, ""] if result.reward_note else []),
        f"Score {_score(result)}; OT distance {d.distance:.4f}, {_placement(result)}.",
        "",
        "| episode | seed | score | return | proxy return | OT distance | demo | converged |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for k, e in enumerate(d.episodes):
        demo = "pooled" if e.demo_index is None else e.demo_index
        lines.append(
            f"| {k + 1} | {result.seeds[k]} | {result.scores[k]:.1f} | {result.returns[k]:.1f} "
            f"| {e.proxy_rewards.sum():.2f} | {e.distance:.4f} | {demo} | {e.converged} |"
        )
    return [*lines, ""]


def _shares_section(result: RunDiagnosis) -> list[str]:
    d = result.diagnosis
    learner = np.concatenate([e.observations for e in d.episodes])
    demos = np.concatenate(_compared_demos(d))
    lines = [
        "## 1. Where the transported cost goes",
        "",
        "Each dimension's share of the transported cost <C, P> (all episodes together): each "
        "matched pair's P_ij C_ij split among the standardised atoms' columns in proportion to "
        "their squared differences (x_ik - y_jk)^2 / |x_i - y_j|^2, a state dimension's "
        "columns summed (with (s_t, s_t+1) atoms, its two copies). The shares sum to 1. "
        "Learner and demo: mean +- std of the raw values.",
        "",
        "| dimension | share | learner | demo |",
        "|---|---|---|---|",
    ]
    top = d.top(TABLE_ROWS)
    for k in top:
        raw = ["", ""]
        if k < learner.shape[1]:  # not the time index
            raw = [f"{x[:, k].mean():.3g} +- {x[:, k].std():.3g}" for x in (learner, demos)]
        lines.append(f"| {d.names[k]} | {d.shares[k]:.1%} | {raw[0]} | {raw[1]} |")
    if len(d.shares) > len(top):
        rest = float(np.sum(np.delete(d.shares, top)))
        lines.append(f"| the other {len(d.shares) - len(top)} | {rest:.1%} | | |")
    return [*lines, "", "![shares](shares.png)", ""]


def _rewards_section(result: RunDiagnosis) -> list[str]:
    e = result.diagnosis.episodes[0]
    proxy, task, half = e.proxy_rewards, e.task_rewards, len(e.proxy_rewards) // 2
    assert task is not None  # a run's episodes have their task rewards
    r = np.corrcoef(proxy, task)[0, 1] if np.ptp(proxy) > 0 and np.ptp(task) > 0 else math.nan
    return [
        "## 2. The proxy reward beside the task reward",
        "",
        f"Episode 1 (seed {result.seeds[0]}): proxy return {proxy.sum():.2f} "
        f"({proxy[:half].sum():.2f} in the first half, {proxy[half:].sum():.2f} in the "
        f"second), per step {proxy.mean():.4f} on average, lowest {proxy.min():.4f} at step "
        f"{int(proxy.argmin())}; task return {task.sum():.1f}, per step {task.mean():.3f}. "
        f"Pearson's r of the two per step: {r:.3f}. The demo's own first {len(proxy)} steps "
        f"get proxy return {_floor(result).proxy_return:.2f}.",
        "",
        "![rewards](rewards.png)",
        "",
    ]


def _calibration_section(result: RunDiagnosis) -> list[str]:
    d = result.diagnosis
    steps, demo_steps = len(d.episodes[0].proxy_rewards), len(_compared_demos(d)[0]) - 1
    floor = _floor(result).distance
    lines = [
        "## 3. The learner among noisy copies of the demonstrator",
        "",
        f"The demo's first {steps} steps with Gaussian noise N(0, sigma^2) in each standardised "
        "dimension (raw: sigma times OOPS's scale, 3 std), and the shipped expert with action "
        f"noise, scored by the same OOPS. The learner: {_placement(result)}.",
    ]
    if demo_steps > steps:
        lines.append(
            f"The demo has {demo_steps} steps, the episodes {steps}: OOPS spreads an episode "
            f"over the whole demo, so even an exact copy of its first {steps} steps is "
            f"{floor:.4f} away: compare the learner with that, not with 0."
        )
    lines += ["", "| compared | OT distance | proxy return | task score |", "|---|---|---|---|"]
    lines += [
        f"| demo + N(0, {c.sigma:g}^2) | {c.distance:.4f} | {c.proxy_return:.2f} | |"
        for c in result.noisy
    ]
    proxy = np.mean([e.proxy_rewards.sum() for e in d.episodes])
    score = np.mean(result.scores)
    lines.append(f"| **the learner** | {d.distance:.4f} | {proxy:.2f} | {score:.1f} |")
    lines += [
        f"| {p.policy} | {p.ot_distance:.4f} | {p.proxy_return:.2f} | {p.task_score:.1f} |"
        for p in result.expert
    ]
    if result.expert_note:
        lines += ["", f"The shipped expert with action noise: {result.expert_note}"]
    return [*lines, "", "![calibration](calibration.png)", ""]


def _plot_shares(result: RunDiagnosis, out: Path) -> Path:
    import matplotlib.pyplot as plt

    d = result.diagnosis
    top = d.top(30)
    fig, ax = plt.subplots(figsize=(7, 1.5 + 0.25 * len(top)))
    ax.barh(range(len(top)), [d.shares[k] for k in top], color="tab:red")
    ax.set_yticks(range(len(top)), [d.names[k] for k in top], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("share of the transported cost <C, P>")
    ax.set_title(f"{result.config.env}: where the OT distance {d.distance:.3f} goes", fontsize=10)
    return _save(fig, out / "shares.png")


def _plot_rewards(result: RunDiagnosis, out: Path) -> Path:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for k, e in enumerate(result.diagnosis.episodes):
        style = {"alpha": 1.0 if k == 0 else 0.35, "lw": 1.0, "label": f"episode {k + 1}"}
        axes[0].plot(e.proxy_rewards, color="tab:blue", **style)
        axes[1].plot(e.task_rewards, color="tab:green", **style)
    for ax, label in zip(axes, ("proxy (OOPS) reward", "task reward"), strict=True):
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[1].set_xlabel("step")
    axes[0].set_title(f"{result.config.env}, {result.config.algo}: reward per step", fontsize=10)
    if len(result.diagnosis.episodes) <= 5:
        axes[0].legend(fontsize=7)
    return _save(fig, out / "rewards.png")


def _plot_calibration(result: RunDiagnosis, out: Path) -> Path:
    import matplotlib.pyplot as plt

    noisy_expert = [(p.noise, p.ot_distance) for p in result.expert if p.noise is not None]
    families = [("demo + N(0, sigma^2): sigma", [(c.sigma, c.distance) for c in result.noisy])]
    families += [("expert + action noise N(0, l^2): l", noisy_expert)] * bool(noisy_expert)
    fig, axes = plt.subplots(1, len(families), figsize=(5 * len(families), 3.8), squeeze=False)
    for ax, (label, points) in zip(axes[0], families, strict=True):
        ax.plot(range(len(points)), [y for _, y in points], "o-", color="tab:gray", label="copies")
        ax.set_xticks(range(len(points)), [f"{x:g}" for x, _ in points])
        ax.axhline(result.diagnosis.distance, color="tab:red", label="the learner")
        ax.set(xlabel=label, ylabel="OT distance <C, P>")
        ax.grid(alpha=0.3)
    others = [p for p in result.expert if p.noise is None]  # zero and random actions
    for p, style in zip(others, ("--", ":"), strict=False):
        axes[0][-1].axhline(p.ot_distance, color="k", ls=style, label=f"{p.policy} actions")
    for ax in axes[0]:
        ax.legend(fontsize=7)
    fig.suptitle(f"{result.config.env}: the learner among noisy demonstrators", fontsize=10)
    return _save(fig, out / "calibration.png")


def _plot_grid(result: RunDiagnosis, out: Path) -> Path:
    import matplotlib.pyplot as plt

    d = result.diagnosis
    dims = [k for k in d.top(GRID_DIMENSIONS) if k < d.episodes[0].observations.shape[1]]
    rows = max(1, -(-len(dims) // 2))
    fig, axes = plt.subplots(rows, 2, figsize=(10, 2.2 * rows), squeeze=False)
    for ax, k in zip(axes.flat, dims, strict=False):
        for i, demo in enumerate(_compared_demos(d)):
            ax.plot(demo[:, k], color="k", lw=1.0, alpha=0.6, label="demo" if i == 0 else None)
        for i, e in enumerate(d.episodes):
            label = "learner" if i == 0 else None
            ax.plot(e.observations[:, k], color="tab:red", lw=1.0, alpha=0.7, label=label)
        ax.set_title(f"{d.names[k]}: {d.shares[k]:.1%} of the cost", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(dims) :]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("step")
    return _save(fig, out / "trajectories.png")


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
