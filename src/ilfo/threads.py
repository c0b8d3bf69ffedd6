"""The environment that holds a process to a number of threads and a set of CPUs: what sweep
workers and labelling's worker processes set before JAX and BLAS start their thread pools."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

CPUS_ENV = "ILFO_CPUS"
"""Comma-separated CPU ids a sweep worker pins itself to (unset: no pinning)."""
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def thread_environment(
    threads: int, cpus: Sequence[int] | None = None, environ: Mapping[str, str] = os.environ
) -> dict[str, str]:
    """The environment variables that hold a run to ``threads`` threads: BLAS and OpenMP pools
    of that size, so that runs side by side do not oversubscribe the cores (OpenBLAS slows
    10-20x under contention: docs/benchmarks.md), and ``cpus`` to pin it to, where given (XLA
    sizes its pools by them). Without CPUs to pin to (Ray places runs, not threads), a
    one-thread run also gets XLA's single-threaded CPU code, added to any ``XLA_FLAGS``."""
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    env = dict.fromkeys(THREAD_VARIABLES, str(threads))
    if cpus is not None:
        env[CPUS_ENV] = ",".join(str(c) for c in cpus)
    elif threads == 1:
        flags = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
        env["XLA_FLAGS"] = f"{environ.get('XLA_FLAGS', '')} {flags}".strip()
    return env
