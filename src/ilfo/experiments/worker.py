"""One run of a sweep, in its own process: ``python -m ilfo.experiments.worker SWEEP_DIR NAME``.

Started by a sweep backend with its threads pinned (``thread_environment``): the CPU set in
``ILFO_CPUS`` (applied here, before JAX starts its thread pools, which size themselves by the
CPUs the process may use) and the BLAS/OpenMP thread counts in the environment. It starts the
run, or resumes it from its newest checkpoint, and records the attempt's start (with the
pinning it got) and its end (done, interrupted, or the error) in ``attempts/NAME.jsonl``.

Exit status: 0 done, 130 interrupted (SIGINT: the run checkpointed first), 1 failed, 75
(``worker_protocol.EXIT_BUSY``) another process holds the run's lock.
"""

from __future__ import annotations

import os
import signal
import sys
import traceback
from collections.abc import Mapping, Sequence

from ilfo.experiments.worker_protocol import EXIT_BUSY, PARENT_SIGNAL_ENV
from ilfo.threads import CPUS_ENV, THREAD_VARIABLES


def pin_from_environment(environ: Mapping[str, str] = os.environ) -> list[int] | None:
    """Apply ``ILFO_CPUS`` to this process (Linux); returns the CPU set now in force."""
    spec = environ.get(CPUS_ENV)
    if spec:
        cpus = {int(c) for c in spec.split(",") if c.strip()}
        os.sched_setaffinity(0, cpus)
    return sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None


def _die_with_parent() -> None:
    """Ask the kernel for SIGINT when the parent process dies (prctl PR_SET_PDEATHSIG)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGINT)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: a killed sweep may leave the run going
        pass


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 2:
        print("usage: python -m ilfo.experiments.worker SWEEP_DIR RUN_NAME", file=sys.stderr)
        return 2
    if os.environ.get(PARENT_SIGNAL_ENV):
        _die_with_parent()
        if os.getppid() == 1:  # the sweep died before the request took effect
            return 130
    cpus = pin_from_environment()
    from ilfo.experiments.attempts import record_attempt
    from ilfo.experiments.sweep import open_sweep, run_status

    sweep = open_sweep(args[0])
    run = sweep.run(args[1])
    threads = {name: os.environ.get(name) for name in (*THREAD_VARIABLES, "XLA_FLAGS")}
    start = {"pid": os.getpid(), "sweep_pid": os.getppid(), "cpus": cpus, "threads": threads}
    record_attempt(sweep, run.name, "start", **start)
    from ilfo.training.run_dir import RunDirInUse

    try:
        if run_status(sweep, run).state != "done":
            train_run(sweep.run_dir(run.name), run.config)
    except KeyboardInterrupt:
        record_attempt(sweep, run.name, "end", status="interrupted")
        return 130
    except RunDirInUse as err:  # another process trains it (or glanced at its lock): no failure
        record_attempt(sweep, run.name, "end", status="busy", error=str(err))
        return EXIT_BUSY
    except BaseException as err:  # recorded for the sweep's status and retries
        message = f"{type(err).__name__}: {err}"
        record_attempt(
            sweep, run.name, "end", status="error", error=message, traceback=traceback.format_exc()
        )
        traceback.print_exc()
        return 1
    record_attempt(sweep, run.name, "end", status="done")
    return 0


def train_run(run_dir: os.PathLike[str] | str, config: Mapping[str, object]) -> None:
    """Train the run in ``run_dir`` to its steps: start it, or resume it where it has a config
    (a run killed before its first checkpoint starts again from step 0)."""
    import warnings
    from pathlib import Path

    from ilfo.compilation_cache import enable_compilation_cache
    from ilfo.training import Trainer, config_from_dict, read_run_config
    from ilfo.training.run_dir import checkpoint_steps

    enable_compilation_cache()
    run_dir = Path(run_dir)
    if (run_dir / "config.json").is_file():
        # The manifest's budget at least: a run cut short by hand (`ilfo train --resume --steps`)
        # would otherwise end below it at every start, never done, requeued forever.
        written = int(read_run_config(run_dir)["steps"])
        budget = max(written, int(config["steps"]))  # type: ignore[call-overload]
        # A last episode may have run past the budget (episodes end whole): such a checkpoint
        # needs no new budget, and would otherwise write its step into config.json as one.
        newest = max([step for step, _ in checkpoint_steps(run_dir)], default=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no complete checkpoint yet": expected here
            trainer = Trainer.resume(
                run_dir, progress=False, steps=budget if budget > max(written, newest) else None
            )
    else:
        trainer = Trainer(config_from_dict(dict(config), run_dir), run_dir, progress=False)
    print(f"{run_dir.name}: training to step {trainer.config.steps:,} from {trainer.step:,}")
    trainer.train()
    print(f"{run_dir.name}: done; last evaluation {trainer.last_eval}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
