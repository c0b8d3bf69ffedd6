"""A sweep's bookkeeping under concurrency and damage: temporary files of their own to each
process, process ids in the attempts records (and CPUs chosen apart by two `sweep run`
processes on one folder), a damaged attempts file or manifest reported, never fatal."""

from __future__ import annotations

import fcntl
import json
import os
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from ilfo.cli import main
from ilfo.experiments import SweepSpec, create_sweep, open_sweep, read_attempts, record_attempt
from ilfo.experiments.sweep import MANIFEST_FILE
from tiny_run import TINY_RUN

TINY = {**TINY_RUN, "steps": 400}
del TINY["env"]  # the sweep spec's axis
HOST = socket.gethostname()
TWO_CPUS = pytest.mark.skipif(
    not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
    reason="needs two CPUs to choose between",
)


def _at_once(tmp_path: Path, setup: str, action: str, processes: int = 6) -> None:
    """Run ``action`` in ``processes`` Python processes released together, each once its
    ``setup`` (the imports) is done; every one must succeed."""
    go = tmp_path / "go"
    script = textwrap.dedent(
        f"""
        import os, sys, time
        from pathlib import Path
        {setup}
        Path(sys.argv[1]).touch()
        while not os.path.exists({str(go)!r}):
            time.sleep(0.001)
        {action}
        """
    )
    ready = [tmp_path / f"ready{i}" for i in range(processes)]
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", script, str(flag)], stderr=subprocess.PIPE, text=True
        )
        for flag in ready
    ]
    try:
        deadline = time.monotonic() + 300
        while not all(flag.exists() for flag in ready):
            assert time.monotonic() < deadline and all(p.poll() is None for p in procs), [
                p.stderr.read() for p in procs if p.poll() is not None
            ]
            time.sleep(0.05)
        go.touch()
        errors = [p.communicate(timeout=300)[1] for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    assert all(p.returncode == 0 for p in procs), errors


# ----------------------------------------------------------------- temporary files
@pytest.mark.integration
def test_processes_writing_one_json_file_at_once_use_temporaries_of_their_own(tmp_path):
    target = tmp_path / "shared.json"
    _at_once(
        tmp_path,
        "from ilfo.files import write_json_atomic",
        f"for i in range(300): write_json_atomic({str(target)!r}, {{'i': i, 'pid': os.getpid()}})",
    )
    assert json.loads(target.read_text())["i"] == 299
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


@pytest.mark.integration
def test_six_processes_creating_one_sweep_at_once(tmp_path):
    """Six processes create the same sweeps at once (each of 20 in turn): each one made once,
    every process handed it."""
    roots = [tmp_path / f"sweep{i}" for i in range(20)]
    spec = f"SweepSpec(seed=(0, 1), config={TINY!r})"
    _at_once(
        tmp_path,
        f"from ilfo.experiments import SweepSpec, create_sweep, expand; expand({spec})",
        f"for root in {[str(r) for r in roots]!r}: create_sweep(root, {spec})",
    )
    for root in roots:
        assert len(open_sweep(root).runs) == 2
        assert sorted(p.name for p in root.iterdir()) == ["attempts", "logs", "runs", MANIFEST_FILE]


def test_another_processs_temporary_manifest_is_no_foreign_file(tmp_path):
    (tmp_path / f".{MANIFEST_FILE}.4242.tmp").write_text("{")  # another process, mid-write
    sweep = create_sweep(tmp_path, SweepSpec(config=TINY))
    assert open_sweep(tmp_path).runs == sweep.runs


# --------------------------------------------------------------- pids in the records
@pytest.fixture
def sleeper():
    """A live process that is not this one (another worker), ended after the test."""
    process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    yield process.pid
    process.kill()
    process.wait()


def test_every_record_carries_the_pid_of_its_worker(tmp_path):
    sweep = create_sweep(tmp_path, SweepSpec(config=TINY))
    (name,) = (r.name for r in sweep.runs)
    record_attempt(sweep, name, "start", cpus=[0])
    record_attempt(sweep, name, "end", status="done")
    record_attempt(sweep, name, "end", status="killed", pid=123)  # for a worker that died
    assert [e["pid"] for e in read_attempts(sweep, name)] == [os.getpid(), os.getpid(), 123]


@TWO_CPUS
def test_a_busy_workers_end_does_not_hide_the_live_worker_before_it(tmp_path, sleeper):
    """Two workers of one run (two `sweep run` processes): the second finds the run's lock
    held and ends at once ("busy"); the first, still training, keeps its CPU."""
    from ilfo.experiments.backends import LocalBackend, cpus_of_live_workers

    sweep = create_sweep(tmp_path, SweepSpec(config=TINY))
    (name,) = (r.name for r in sweep.runs)
    cpus = sorted(os.sched_getaffinity(0))
    record_attempt(sweep, name, "start", pid=os.getpid(), cpus=cpus[:1])  # training
    record_attempt(sweep, name, "start", pid=sleeper, cpus=cpus[1:2])
    record_attempt(sweep, name, "end", status="busy", pid=sleeper)
    assert cpus_of_live_workers(sweep) == set(cpus[:1])
    assert LocalBackend(workers=1).cpu_set(sweep, 0) == cpus[1:2]
    # An end written before ilfo kept pids ends the latest start, as it always did.
    with sweep.attempts_file(name).open("a") as f:
        f.write(json.dumps({"event": "end", "status": "done"}) + "\n")
    assert cpus_of_live_workers(sweep) == set()


@pytest.mark.integration
@TWO_CPUS
def test_a_launched_worker_holds_its_cpus_before_it_records_its_start(tmp_path, monkeypatch):
    """A second `sweep run` process choosing CPUs while the first's worker is still loading
    (its start not yet recorded) passes over the CPUs that worker was given; the choice and
    the launch record are made under the sweep's launch lock."""
    from ilfo.experiments import backends
    from ilfo.experiments.sweep import LAUNCH_LOCK

    sweep = create_sweep(tmp_path, SweepSpec(config=TINY))
    (name,) = (r.name for r in sweep.runs)
    cpus = sorted(os.sched_getaffinity(0))
    monkeypatch.setattr(
        backends, "worker_command", lambda *_: [sys.executable, "-c", "import time; time.sleep(60)"]
    )
    first = backends.LocalBackend(workers=1)
    chose = first.cpu_set

    def cpu_set_under_the_lock(*args):
        with open(tmp_path / LAUNCH_LOCK, "a") as lock, pytest.raises(BlockingIOError):
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)  # held by the launch
        return chose(*args)

    monkeypatch.setattr(first, "cpu_set", cpu_set_under_the_lock)
    job = first.start(sweep, name, 0)
    try:
        (launch,) = read_attempts(sweep, name)
        assert launch["event"] == "launch" and launch["pid"] == job.process.pid
        assert launch["cpus"] == cpus[:1] and launch["sweep_pid"] == os.getpid()
        assert backends.LocalBackend(workers=1).cpu_set(sweep, 0) == cpus[1:2]
    finally:
        job.process.kill()
        job.process.wait()
    assert backends.LocalBackend(workers=1).cpu_set(sweep, 0) == cpus[:1]  # dead: free


# ------------------------------------------------------------------------------ damage
def test_a_damaged_attempts_file_is_reported_and_skipped(tmp_path, capsys):
    sweep = create_sweep(tmp_path, SweepSpec(seed=(0, 1), config=TINY))
    damaged, fine = (r.name for r in sweep.runs)
    path = sweep.attempts_file(damaged)
    record_attempt(sweep, damaged, "end", status="error", error="boom")
    with path.open("ab") as f:
        f.write(b"\xff\xfe not utf-8\n[1, 2]\n" + b"[" * 100_000 + b"\n")
        f.write(
            json.dumps({"event": "start", "pid": 1, "cpus": "abc", "host": HOST}).encode() + b"\n"
        )
    record_attempt(sweep, fine, "end", status="error", error="bang")
    with pytest.warns(UserWarning, match=r"damaged: line\(s\) 2, 3, 4") as caught:
        statuses = {s.name: s for s in sweep.statuses()}
    assert str(path) in str(caught[0].message)
    assert statuses[damaged].failures == 1 and statuses[damaged].error == "boom"
    assert statuses[fine].failures == 1 and statuses[fine].error == "bang"
    from ilfo.experiments.backends import cpus_of_live_workers

    with pytest.warns(UserWarning):
        assert cpus_of_live_workers(sweep) == set()  # "abc" claims nothing
    assert main(["sweep", "status", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert f"ilfo: warning: {path} is damaged" in err and "Traceback" not in err


def test_a_torn_line_from_a_kill_is_skipped_without_a_warning(tmp_path, recwarn):
    sweep = create_sweep(tmp_path, SweepSpec(config=TINY))
    (name,) = (r.name for r in sweep.runs)
    record_attempt(sweep, name, "start", pid=1)
    with sweep.attempts_file(name).open("a") as f:
        f.write('{"event": "end", "ti')  # killed mid-write
    record_attempt(sweep, name, "end", status="killed", pid=1)
    assert [e["event"] for e in read_attempts(sweep, name)] == ["start", "end"]
    assert not [w for w in recwarn if "damaged" in str(w.message)]


def _edit_manifest(root: Path, edit) -> Path:
    path = root / MANIFEST_FILE
    raw = json.loads(path.read_text())
    path.write_text(edit(raw))
    return path


def test_a_manifest_run_with_steps_that_are_no_number_is_a_one_line_error(tmp_path, capsys):
    create_sweep(tmp_path, SweepSpec(config=TINY))

    def edit(raw):
        raw["runs"][0]["config"]["steps"] = "x"
        return json.dumps(raw)

    path = _edit_manifest(tmp_path, edit)
    with pytest.raises(ValueError, match="steps 'x', not a whole number") as info:
        open_sweep(tmp_path)
    assert str(path) in str(info.value)
    assert main(["sweep", "status", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err


def test_a_manifest_nested_too_deeply_is_a_one_line_error(tmp_path, capsys):
    create_sweep(tmp_path, SweepSpec(config=TINY))
    path = _edit_manifest(tmp_path, lambda raw: '{"spec": ' + "[" * 100_000 + "]" * 100_000 + "}")
    assert main(["sweep", "status", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err and "nested too deeply" in err
