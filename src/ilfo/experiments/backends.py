"""Running a sweep's runs: one scheduler, two backends.

``run_sweep`` keeps as many runs going as the backend has slots, each a worker process
(``ilfo.experiments.worker``) that trains or resumes one run; ``run_sweeps`` does so over
several sweeps as one queue. A run that ends with an error is started again while its
failures are within the sweep's ``retries``; a run that another process is training (its run
lock is held) is waited for, not started twice. Ctrl-C interrupts every worker (each
checkpoints first) and returns; starting the sweep again continues it.

- ``LocalBackend`` (the default, no dependency): a pool sized to this machine's cores, each
  worker pinned to its own ``cores_per_run`` CPUs with BLAS/OpenMP threads to match.
- ``RayBackend``: each run a Ray task holding ``cores_per_run`` CPUs of a cluster (or a local
  Ray instance); the sweep directory must be on a file system every node sees. A node lost
  under a run makes Ray start the task again, and the worker resumes from the checkpoint.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Collection, Iterator, Sequence
from typing import Any, Protocol

from ilfo.experiments.attempts import (
    claimed_cpus,
    read_attempts,
    record_attempt,
    unended_workers,
)
from ilfo.experiments.sweep import LAUNCH_LOCK, RunStatus, Sweep, run_status, summary, sweep_labels
from ilfo.experiments.worker_protocol import EXIT_BUSY, PARENT_SIGNAL_ENV
from ilfo.threads import thread_environment

EXIT_INTERRUPTED = 130
PROGRESS_SECONDS = 10.0
"""How often the running runs' steps are read for the progress display."""


class Job(Protocol):
    """A started worker."""

    name: str

    def poll(self) -> int | None:
        """Its exit status once it has ended (negative: killed by that signal), else None."""
        ...

    def interrupt(self) -> None:
        """Ask it to checkpoint and stop."""
        ...


class Backend(Protocol):
    """Where workers run."""

    slots: int
    """How many runs at once."""

    def watch(self, sweeps: Sequence[Sweep]) -> None:
        """Told, before any start, every sweep whose runs the scheduler may start."""
        ...

    def start(self, sweep: Sweep, name: str, slot: int) -> Job: ...

    def close(self) -> None: ...


def worker_command(sweep: Sweep, name: str) -> list[str]:
    return [sys.executable, "-m", "ilfo.experiments.worker", str(sweep.root), name]


# ---------------------------------------------------------------------------------- local
class _ProcessJob:
    def __init__(self, name: str, process: subprocess.Popen[bytes]) -> None:
        self.name, self.process = name, process

    def poll(self) -> int | None:
        return self.process.poll()

    def interrupt(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)


def _alive(pid: object) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    return True


def cpus_of_live_workers(sweep: Sweep, exclude_pids: Collection[int] = ()) -> set[int]:
    """The CPUs that the sweep's live workers on this host were pinned to (each worker's
    latest launch or start record without an end of its pid after it, whose process is alive:
    ``attempts.unended_workers``), other than ``exclude_pids``'s: what another ``sweep run``
    process on the same sweep holds."""
    host = socket.gethostname()
    claimed: set[int] = set()
    for run in sweep.runs:
        for record in unended_workers(read_attempts(sweep, run.name)):
            pid = record.get("pid")
            if record.get("host") == host and pid not in exclude_pids and _alive(pid):
                claimed |= claimed_cpus(record)
    return claimed


@contextlib.contextmanager
def _launch_lock(sweeps: Collection[Sweep]) -> Iterator[None]:
    """Hold every sweep's ``LAUNCH_LOCK`` (in one order, so that two processes cannot each
    wait on the other's): while a process chooses a worker's CPUs and records its launch, no
    other chooses any on these sweeps."""
    with contextlib.ExitStack() as stack:
        for root in sorted({str(sweep.root.resolve()) for sweep in sweeps}):
            lock = stack.enter_context(open(os.path.join(root, LAUNCH_LOCK), "a"))
            fcntl.flock(lock, fcntl.LOCK_EX)
        yield


class LocalBackend:
    """Worker processes on this machine, each pinned to ``cores_per_run`` CPUs of its own: CPUs
    that another ``sweep run`` process's live workers hold, on any sweep the scheduler
    watches, are passed over where enough others are free (two processes with
    disjoint ``--only`` would otherwise both pin their first worker to the first CPU)."""

    def __init__(self, cores_per_run: int = 1, workers: int | None = None) -> None:
        cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
        count = len(cpus) if cpus is not None else os.cpu_count() or 1
        if cores_per_run < 1:
            raise ValueError(f"cores_per_run must be >= 1, got {cores_per_run}")
        if cores_per_run > count:
            raise ValueError(f"cores_per_run {cores_per_run} exceeds this machine's {count} CPUs")
        fit = count // cores_per_run
        if workers is not None and not 1 <= workers <= fit:
            raise ValueError(
                f"workers must be between 1 and {fit} ({count} CPUs / {cores_per_run} per run), "
                f"got {workers}"
            )
        self.cores_per_run = cores_per_run
        self.slots = fit if workers is None else workers
        self.cpus = cpus
        self.cpu_sets: list[list[int] | None] = (
            [cpus[i * cores_per_run : (i + 1) * cores_per_run] for i in range(self.slots)]
            if cpus is not None
            else [None] * self.slots
        )
        self._jobs: dict[int, _ProcessJob] = {}  # slot -> its latest job
        self._sweeps: dict[str, Sweep] = {}  # root -> a sweep the scheduler may start runs of

    def cpu_set(self, sweep: Sweep, slot: int) -> list[int] | None:
        """The CPUs for a new worker in ``slot``: the first ``cores_per_run`` of this process's
        CPUs that neither its other slots nor another process's live workers on the sweep (or
        on the other sweeps it watches) hold. Where that leaves too few (more
        workers than CPUs), the slot's own share, unless another of its live slots holds it
        now: then CPUs that only other processes' workers hold, which come free when those
        end, rather than doubling up on its own."""
        if self.cpus is None:
            return None
        ours = {slot_ for slot_, job in self._jobs.items() if job.poll() is None}
        ours_pids = {self._jobs[s].process.pid for s in ours}
        self._sweeps[str(sweep.root)] = sweep
        taken: set[int] = set()
        for seen in self._sweeps.values():
            taken |= cpus_of_live_workers(seen, ours_pids)
        held_by_ours: set[int] = set()
        for other in ours - {slot}:
            held_by_ours.update(self.cpu_sets[other] or ())
        free = [c for c in self.cpus if c not in taken | held_by_ours]
        if len(free) < self.cores_per_run:
            own = self.cpu_sets[slot]
            if own is None or not held_by_ours & set(own):
                return own
            free += [c for c in self.cpus if c not in held_by_ours and c not in free]
            if len(free) < self.cores_per_run:
                return own
        self.cpu_sets[slot] = free[: self.cores_per_run]
        return self.cpu_sets[slot]

    def watch(self, sweeps: Sequence[Sweep]) -> None:
        """Pass over the CPUs that other processes' live workers hold on these sweeps too (a
        process whose first sweep's runs are all held elsewhere starts another sweep's)."""
        self._sweeps.update((str(sweep.root), sweep) for sweep in sweeps)

    def start(self, sweep: Sweep, name: str, slot: int) -> Job:
        """Start the run's worker on CPUs of its own, recorded at once as its launch (the
        worker records its start only once Python and ilfo are loaded, seconds later)."""
        log = sweep.log_file(name)
        log.parent.mkdir(parents=True, exist_ok=True)
        self._sweeps[str(sweep.root)] = sweep
        with _launch_lock(list(self._sweeps.values())), log.open("ab") as out:
            cpus = self.cpu_set(sweep, slot)
            env = {
                **os.environ,
                **thread_environment(self.cores_per_run, cpus),
                PARENT_SIGNAL_ENV: "1",
            }
            process = subprocess.Popen(
                worker_command(sweep, name),
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # Ctrl-C at the terminal reaches the sweep, which relays it
            )
            record_attempt(sweep, name, "launch", pid=process.pid, cpus=cpus, sweep_pid=os.getpid())
        self._jobs[slot] = _ProcessJob(name, process)
        return self._jobs[slot]

    def close(self) -> None:
        pass


# ------------------------------------------------------------------------------------ Ray
def _ray_worker(command: list[str], env: dict[str, str], log: str) -> int:
    """A Ray task: one worker process on the node Ray chose; Ray's cancel interrupts it."""
    environ = {**os.environ, **env}
    with open(log, "ab") as out:
        process = subprocess.Popen(command, env=environ, stdout=out, stderr=subprocess.STDOUT)
        try:
            return process.wait()
        except KeyboardInterrupt:  # ray.cancel
            process.send_signal(signal.SIGINT)
            return process.wait()


class _RayJob:
    def __init__(self, name: str, ref: Any, ray: Any) -> None:
        self.name, self.ref, self._ray = name, ref, ray
        self._exit: int | None = None

    def poll(self) -> int | None:
        if self._exit is not None:
            return self._exit
        ready, _ = self._ray.wait([self.ref], timeout=0)
        if not ready:
            return None
        try:
            self._exit = int(self._ray.get(self.ref))
        except self._ray.exceptions.TaskCancelledError:
            self._exit = EXIT_INTERRUPTED
        except self._ray.exceptions.RayError:  # its node lost beyond Ray's retries
            self._exit = -int(signal.SIGKILL)
        return self._exit

    def interrupt(self) -> None:
        self._ray.cancel(self.ref)


class RayBackend:
    """Each run a Ray task of ``cores_per_run`` CPUs; ``address`` None starts a local Ray
    instance (``num_cpus`` of this machine's), ``"auto"`` or ``HOST:PORT`` joins a cluster."""

    def __init__(
        self,
        address: str | None = None,
        cores_per_run: int = 1,
        num_cpus: int | None = None,
        node_retries: int = 3,
    ) -> None:
        try:
            import ray
        except ImportError:
            raise ValueError(
                "the Ray backend needs Ray: pip install -e '.[ray]' (or pip install 'ilfo[ray]')"
            ) from None
        if cores_per_run < 1:
            raise ValueError(f"cores_per_run must be >= 1, got {cores_per_run}")
        self._ray = ray
        self._owns = not ray.is_initialized()
        if self._owns:
            kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
            if address is None:
                kwargs["num_cpus"] = num_cpus
            else:
                kwargs["address"] = address
            ray.init(**kwargs)
        total = int(ray.cluster_resources().get("CPU", 1))
        if cores_per_run > total:
            raise ValueError(f"cores_per_run {cores_per_run} exceeds the cluster's {total} CPUs")
        self.cores_per_run = cores_per_run
        self.slots = max(1, total // cores_per_run)
        self._task = ray.remote(num_cpus=cores_per_run, max_retries=node_retries)(_ray_worker)

    def start(self, sweep: Sweep, name: str, slot: int) -> Job:
        log = sweep.log_file(name)
        log.parent.mkdir(parents=True, exist_ok=True)
        env = thread_environment(self.cores_per_run)
        ref = self._task.remote(worker_command(sweep, name), env, str(log.resolve()))
        return _RayJob(name, ref, self._ray)

    def watch(self, sweeps: Sequence[Sweep]) -> None:
        pass  # Ray places each task on CPUs it holds

    def close(self) -> None:
        if self._owns:
            self._ray.shutdown()


# ------------------------------------------------------------------------------ scheduler
_Key = tuple[int, str]  # (the sweep's index, the run's name)


def run_sweep(
    sweep: Sweep,
    backend: Backend,
    *,
    poll_seconds: float = 1.0,
    on_change: Callable[[list[RunStatus], str], None] | None = None,
    names: Collection[str] | None = None,
) -> list[RunStatus]:
    """Run the sweep's unfinished runs to their ends (see the module); returns every run's
    final status. ``names`` limits that to some runs (``select_runs``; the others are left
    as they are, and still reported). ``on_change(statuses, message)`` is called at each start
    and end (and about every ``poll_seconds`` with an empty message) for progress display."""
    chosen = None if names is None else [names]
    return run_sweeps(
        [sweep], backend, poll_seconds=poll_seconds, on_change=on_change, names=chosen
    )


def run_sweeps(
    sweeps: Sequence[Sweep],
    backend: Backend,
    *,
    poll_seconds: float = 1.0,
    on_change: Callable[[list[RunStatus], str], None] | None = None,
    names: Sequence[Collection[str]] | None = None,
) -> list[RunStatus]:
    """``run_sweep`` over several sweeps as one queue, in their order: a slot that one sweep's
    last runs leave free (or its runs that another process trains) takes the next sweep's
    runs at once, rather than idling until the sweep ends (a run that is retried or comes free
    again rejoins the queue after its own sweep's runs, before later sweeps'). ``names``, one
    collection per sweep, limits each to those runs. Returns every run's final status, sweep
    by sweep; with several sweeps, the messages name runs as ``<label>/<run>``
    (``sweep_labels``)."""
    roots = [sweep.root.resolve() for sweep in sweeps]
    if len(set(roots)) != len(roots):
        raise ValueError(f"a sweep is given twice: {[str(s.root) for s in sweeps]}")
    if names is not None and (len(names) != len(sweeps) or any(isinstance(n, str) for n in names)):
        raise ValueError(f"names must be one collection of run names per sweep, got {names!r}")
    chosen: set[_Key] = set()
    for i, sweep in enumerate(sweeps):
        in_sweep = {run.name for run in sweep.runs}
        wanted = set(in_sweep if names is None else names[i])
        if unknown := wanted - in_sweep:
            raise KeyError(f"{sweep.root} has no runs named {sorted(unknown)}")
        chosen |= {(i, name) for name in wanted}
    return _schedule(list(sweeps), chosen, backend, poll_seconds, on_change)


def _schedule(
    sweeps: list[Sweep],
    chosen: set[_Key],
    backend: Backend,
    poll_seconds: float,
    on_change: Callable[[list[RunStatus], str], None] | None,
) -> list[RunStatus]:
    queue = _Queue(sweeps, chosen, backend, on_change)
    backend.watch(sweeps)
    try:
        while queue.busy:
            queue.start_runs()
            time.sleep(poll_seconds)
            queue.collect_ended()
            queue.follow_elsewhere()
            queue.refresh_progress()
            queue.notify("")
    except KeyboardInterrupt:
        queue.interrupt()
        raise
    finally:
        backend.close()
    return [queue.refresh(key) for key in queue.runs]


class _Queue:
    """The scheduler's state: the chosen runs waiting for a slot, those running in a slot,
    and those another process trains (waited for)."""

    def __init__(
        self,
        sweeps: list[Sweep],
        chosen: set[_Key],
        backend: Backend,
        on_change: Callable[[list[RunStatus], str], None] | None,
    ) -> None:
        self.sweeps, self.backend = sweeps, backend
        self.runs = {(i, run.name): run for i, sweep in enumerate(sweeps) for run in sweep.runs}
        self.statuses = {
            (i, status.name): status
            for i, sweep in enumerate(sweeps)
            for status in sweep.statuses()
        }
        statuses = self.statuses.items()
        self.queue = [key for key, s in statuses if s.state == "pending" and key in chosen]
        self.elsewhere = [key for key, s in statuses if s.state == "running" and key in chosen]
        self.active: dict[int, tuple[_Key, Job]] = {}  # slot -> its run and job
        self.on_change = on_change or (lambda statuses, message: None)
        self.last_progress = time.monotonic()
        self.labels = sweep_labels(sweeps)
        self.ends_at_start: dict[_Key, int] = {}

    @property
    def busy(self) -> bool:
        return bool(self.queue or self.active or self.elsewhere)

    def notify(self, message: str) -> None:
        self.on_change(list(self.statuses.values()), message)

    def label(self, key: _Key) -> str:
        return key[1] if len(self.sweeps) == 1 else f"{self.labels[key[0]]}/{key[1]}"

    def refresh(self, key: _Key) -> RunStatus:
        self.statuses[key] = run_status(self.sweeps[key[0]], self.runs[key])
        return self.statuses[key]

    def enqueue(self, key: _Key) -> None:
        """After its sweep's queued runs, before later sweeps'."""
        later = [i for i, queued in enumerate(self.queue) if queued[0] > key[0]]
        self.queue.insert(later[0] if later else len(self.queue), key)

    def ends_recorded(self, key: _Key) -> int:
        return sum(e.get("event") == "end" for e in read_attempts(self.sweeps[key[0]], key[1]))

    def start_runs(self) -> None:
        """Fill the free slots from the queue."""
        for slot in range(self.backend.slots):
            if slot not in self.active and self.queue:
                key = self.queue.pop(0)
                state = self.refresh(key).state  # another process may have started it since
                if state != "pending":
                    if state == "running":
                        self.elsewhere.append(key)
                    continue
                self.ends_at_start[key] = self.ends_recorded(key)
                self.active[slot] = key, self.backend.start(self.sweeps[key[0]], key[1], slot)
                self.notify(f"started {self.label(key)}")

    def collect_ended(self) -> None:
        """Free the slots of the runs that ended; queue again those that may go on."""
        for slot, (key, job) in list(self.active.items()):
            code = job.poll()
            if code is None:
                continue
            del self.active[slot]
            if code != EXIT_INTERRUPTED and self.ends_recorded(key) == self.ends_at_start[key]:
                # Killed (OOM, SIGKILL, a lost node), or it failed before it could record
                # its end (a full disk, a bad pin): counted as a failure, so that the
                # retries bound it.
                _record_killed(self.sweeps[key[0]], key[1], job, code)
            status = self.refresh(key)
            if status.state == "pending":
                self.enqueue(key)  # an error within the retries, or an interruption
            elif status.state == "running":  # another process trains it: wait for that
                self.elsewhere.append(key)
            self.notify(f"{self.label(key)}: {_ended(status, code)}")

    def follow_elsewhere(self) -> None:
        """Queue again the runs another process trained and left unfinished."""
        for key in list(self.elsewhere):
            status = self.refresh(key)
            if status.state != "running":
                self.elsewhere.remove(key)
                if status.state == "pending":
                    self.enqueue(key)

    def refresh_progress(self) -> None:
        """Read the running runs' steps, every PROGRESS_SECONDS."""
        if time.monotonic() - self.last_progress >= PROGRESS_SECONDS:
            for key, _ in self.active.values():
                self.refresh(key)
            self.last_progress = time.monotonic()

    def interrupt(self) -> None:
        """Interrupt every worker, and wait for them to end (each checkpoints first)."""
        for _, job in self.active.values():
            job.interrupt()
        deadline = time.monotonic() + 300
        while self.active and time.monotonic() < deadline:
            for slot, (_, job) in list(self.active.items()):
                if job.poll() is not None:
                    del self.active[slot]
            time.sleep(0.2)


def _record_killed(sweep: Sweep, name: str, job: Job, code: int) -> None:
    """The end of a worker that exited without recording its own, with its pid (where known:
    a Ray task's is not), so that its launch and start no longer hold its CPUs."""
    pid = getattr(getattr(job, "process", None), "pid", None)
    record_attempt(sweep, name, "end", status="killed", error=f"worker exit {code}", pid=pid)


def _ended(status: RunStatus, code: int) -> str:
    if status.state == "done":
        return "done"
    if code == EXIT_INTERRUPTED:
        return "interrupted (checkpointed; it continues)"
    if code == EXIT_BUSY:
        return "held by another process; not counted as a failure"
    if status.state == "failed":
        return f"failed {status.failures} times, given up: {status.error}"
    return f"failed ({status.error}); will retry"


def progress_line(statuses: list[RunStatus]) -> str:
    """One line: counts by state and the steps done of all."""
    counts = summary(statuses)
    share = counts["steps_done"] / max(1, counts["steps_total"])
    unresumable = f", {counts['unresumable']} unresumable" if counts["unresumable"] else ""
    return (
        f"{counts['done']} done, {counts['running']} running, {counts['failed']} failed, "
        f"{counts['pending']} pending{unresumable}; "
        f"{counts['steps_done']:,}/{counts['steps_total']:,} steps ({share:.1%})"
    )
