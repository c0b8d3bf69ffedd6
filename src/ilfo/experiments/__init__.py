"""Experiments: sweeps of many runs (``sweep``: the manifest and each run's state on disk;
``attempts``: each run's records of its workers' starts and ends; ``backends``: the
scheduler, local or on Ray; ``worker``: one run in its own process) and reports over them
(``stats``, ``report``, ``paper``)."""

from ilfo.experiments.attempts import read_attempts, record_attempt
from ilfo.experiments.backends import (
    LocalBackend,
    RayBackend,
    progress_line,
    run_sweep,
    run_sweeps,
)
from ilfo.experiments.sweep import (
    RunStatus,
    Sweep,
    SweepRun,
    SweepSpec,
    create_sweep,
    expand,
    matching_sweep,
    open_sweep,
    parse_seeds,
    run_status,
    select_runs,
    snapshot_sweep,
    summary,
    sweep_labels,
)

__all__ = [
    "LocalBackend",
    "RayBackend",
    "RunStatus",
    "Sweep",
    "SweepRun",
    "SweepSpec",
    "create_sweep",
    "expand",
    "matching_sweep",
    "open_sweep",
    "parse_seeds",
    "progress_line",
    "read_attempts",
    "record_attempt",
    "run_status",
    "run_sweep",
    "run_sweeps",
    "select_runs",
    "snapshot_sweep",
    "summary",
    "sweep_labels",
]
