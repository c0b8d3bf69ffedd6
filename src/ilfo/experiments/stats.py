"""Aggregate statistics of final scores over seeds and tasks, as rliable computes them
(Agarwal et al., "Deep RL at the Edge of the Statistical Precipice", NeurIPS 2021).

ilfo has its own small implementation instead of depending on rliable: rliable pins
``arch==5.3.0``, whose wheels predate NumPy 2 (ilfo needs NumPy >= 2.1), and pulls in pandas and
seaborn for figures ilfo draws with matplotlib. The definitions follow rliable's: the
interquartile mean of all runs pooled over tasks (``scipy.stats.trim_mean`` at 25%), the mean and
the median over tasks of each task's mean run, percentile confidence intervals of a stratified
bootstrap (the runs of each task resampled with replacement on their own), performance profiles
(the share of runs scoring above tau) and the probability of improvement (Mann-Whitney U of each
task, averaged over tasks). Tests compare them with SciPy and with hand computations.

A score set is a 2-D array ``(runs, tasks)``: one row per seed, one column per task; NaN marks a
missing run of a task (tasks may have different numbers of seeds).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats as scipy_stats

Aggregate = Callable[[np.ndarray], float]


def _runs(scores: np.ndarray) -> np.ndarray:
    scores = np.asarray(scores, dtype=float)
    if scores.ndim == 1:
        scores = scores[:, None]
    if scores.ndim != 2 or scores.size == 0:
        raise ValueError(f"scores must be a non-empty (runs, tasks) array, got {scores.shape}")
    return scores


def _task_columns(scores: np.ndarray) -> list[np.ndarray]:
    """Each task's finite runs (tasks without any left out)."""
    columns = [scores[np.isfinite(scores[:, t]), t] for t in range(scores.shape[1])]
    return [c for c in columns if c.size]


def iqm(scores: np.ndarray) -> float:
    """Interquartile mean of all runs of all tasks: the mean of the middle 50% (the lowest and
    highest 25% of the pooled scores trimmed)."""
    values = _runs(scores)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return float("nan")
    return float(scipy_stats.trim_mean(values, 0.25))


def _task_means(scores: np.ndarray) -> np.ndarray:
    """Each task's mean over its finite runs (tasks without any left out)."""
    return np.array([c.mean() for c in _task_columns(_runs(scores))])


def mean(scores: np.ndarray) -> float:
    """Mean over tasks of each task's mean run, as rliable's ``aggregate_mean`` (each task
    weighted alike, however many seeds it has)."""
    means = _task_means(scores)
    return float(means.mean()) if means.size else float("nan")


def median(scores: np.ndarray) -> float:
    """Median over tasks of each task's mean run, as rliable's ``aggregate_median`` (on one
    task: that task's mean run)."""
    means = _task_means(scores)
    return float(np.median(means)) if means.size else float("nan")


@dataclass(frozen=True)
class Interval:
    """A point estimate and its confidence interval."""

    value: float
    low: float
    high: float

    def __str__(self) -> str:
        return f"{self.value:.2f} [{self.low:.2f}, {self.high:.2f}]"


def _resample_indices(rng: np.random.Generator, counts: list[int]) -> list[np.ndarray]:
    return [rng.integers(0, n, size=n) for n in counts]


def _rowwise_task_means(pooled: np.ndarray, counts: list[int]) -> np.ndarray:
    """(resamples, tasks) means of each task's block of a (resamples, runs) pooled array."""
    starts = np.cumsum([0, *counts[:-1]])
    return np.add.reduceat(pooled, starts, axis=1) / np.asarray(counts)


_ROWWISE: dict[Aggregate, Callable[[np.ndarray, list[int]], np.ndarray]] = {
    iqm: lambda pooled, counts: scipy_stats.trim_mean(pooled, 0.25, axis=1),
    mean: lambda pooled, counts: _rowwise_task_means(pooled, counts).mean(axis=1),
    median: lambda pooled, counts: np.median(_rowwise_task_means(pooled, counts), axis=1),
}
"""The built-in aggregates computed for all resamples at once, from the pooled resampled runs
and each task's number of runs."""


def stratified_bootstrap(
    scores: np.ndarray,
    aggregate: Aggregate = iqm,
    *,
    resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """``aggregate(scores)`` and its percentile confidence interval from ``resamples``
    stratified bootstrap samples: each task's runs are drawn with replacement from that task's
    own runs (missing runs left out), the tasks kept as they are."""
    scores = _runs(scores)
    columns = _task_columns(scores)
    if not columns:
        nan = float("nan")
        return Interval(nan, nan, nan)
    rng = np.random.default_rng(seed)
    # (resamples, runs) of pooled scores: each task's runs drawn from its own.
    pooled = np.concatenate(
        [c[rng.integers(0, c.size, size=(resamples, c.size))] for c in columns], axis=1
    )
    rowwise = _ROWWISE.get(aggregate)
    if rowwise is not None:
        samples = rowwise(pooled, [c.size for c in columns])
    else:  # any other aggregate of a (runs, tasks) array: one call per resample
        bounds = np.cumsum([0] + [c.size for c in columns])
        width = max(c.size for c in columns)
        samples = np.empty(resamples)
        for b in range(resamples):
            picked = np.full((width, len(columns)), np.nan)
            for t in range(len(columns)):
                part = pooled[b, bounds[t] : bounds[t + 1]]
                picked[: part.size, t] = part
            samples[b] = aggregate(picked)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(samples, [tail, 100 - tail])
    return Interval(aggregate(scores), float(low), float(high))


def performance_profile(scores: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """For each threshold tau, the share of all runs (pooled over tasks) scoring above it."""
    values = _runs(scores)
    values = values[np.isfinite(values)]
    taus = np.asarray(taus, dtype=float)
    if values.size == 0:
        return np.full(taus.shape, np.nan)
    return (values[None, :] > taus[:, None]).mean(axis=1)


def performance_profile_band(
    scores: np.ndarray,
    taus: np.ndarray,
    *,
    resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The profile and its pointwise stratified-bootstrap percentile band: (profile, low,
    high), each of ``taus``' shape."""
    scores = _runs(scores)
    columns = _task_columns(scores)
    taus = np.asarray(taus, dtype=float)
    if not columns:  # no finite run: no profile
        nan = np.full(taus.shape, np.nan)
        return nan, nan.copy(), nan.copy()
    rng = np.random.default_rng(seed)
    samples = np.empty((resamples, taus.size))
    counts = [c.size for c in columns]
    for b in range(resamples):
        pooled = np.concatenate(
            [c[idx] for c, idx in zip(columns, _resample_indices(rng, counts), strict=True)]
        )
        samples[b] = (pooled[None, :] > taus[:, None]).mean(axis=1)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(samples, [tail, 100 - tail], axis=0)
    return performance_profile(scores, taus), low, high


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y): for each task, the probability that a run of X scores above a run of Y (ties
    count a half: the Mann-Whitney U statistic over the pairs), averaged over the tasks. ``x``
    and ``y`` are (runs, tasks) arrays of the same tasks."""
    x, y = _runs(x), _runs(y)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x and y must have the same tasks, got {x.shape[1]} and {y.shape[1]}")
    per_task = []
    for t in range(x.shape[1]):
        a, b = x[np.isfinite(x[:, t]), t], y[np.isfinite(y[:, t]), t]
        if a.size and b.size:
            greater = (a[:, None] > b[None, :]).mean()
            ties = (a[:, None] == b[None, :]).mean()
            per_task.append(greater + 0.5 * ties)
    return float(np.mean(per_task)) if per_task else float("nan")


def probability_of_improvement_interval(
    x: np.ndarray,
    y: np.ndarray,
    *,
    resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> Interval:
    """``probability_of_improvement(x, y)`` with its stratified-bootstrap percentile interval
    (the runs of X and of Y resampled within each task)."""
    x, y = _runs(x), _runs(y)
    rng = np.random.default_rng(seed)
    samples = np.empty(resamples)

    def resample(scores: np.ndarray) -> np.ndarray:
        out = np.full(scores.shape, np.nan)
        for t in range(scores.shape[1]):
            column = scores[np.isfinite(scores[:, t]), t]
            if column.size:
                out[: column.size, t] = column[rng.integers(0, column.size, column.size)]
        return out

    for b in range(resamples):
        samples[b] = probability_of_improvement(resample(x), resample(y))
    tail = 100 * (1 - confidence) / 2
    low, high = np.nanpercentile(samples, [tail, 100 - tail])
    return Interval(probability_of_improvement(x, y), float(low), float(high))
