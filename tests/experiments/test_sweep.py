"""Sweeps: manifest expansion, run states read off disk, the scheduler's skip/resume/retry
bookkeeping (with a fake backend), and one real local sweep killed and started again."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ilfo.experiments import (
    SweepSpec,
    create_sweep,
    expand,
    open_sweep,
    parse_seeds,
    read_attempts,
    record_attempt,
    run_status,
    run_sweep,
    run_sweeps,
    select_runs,
    snapshot_sweep,
)
from ilfo.experiments.worker import pin_from_environment
from ilfo.threads import thread_environment
from ilfo.training import RunLock
from ilfo.training.run_dir import (
    CHECKPOINT_FILES,
    CONFIG_FILE,
    FINAL_POLICY_FILE,
    REPLAY_FILE,
    REPLAY_OMITTED,
)
from tiny_run import TINY_RUN

TINY = {**{k: v for k, v in TINY_RUN.items() if k != "env"}, "steps": 400}  # env: an axis


def test_expansion_names_order_and_settings():
    spec = SweepSpec(
        env=("Hopper-v5",),
        algo=("oops-td3", "pwil-td3"),
        num_demos=(1, 4),
        seed=parse_seeds(["0-1"]),
        config={**TINY, "oops": {"reg": 0.1}},
    )
    runs = expand(spec)
    assert len(runs) == 2 * 2 * 2
    assert runs[0].name == "Hopper-v5__oops-td3__demos1__0"
    assert [r.config["seed"] for r in runs] == [0] * 4 + [1] * 4  # seed-major
    oops = [r for r in runs if r.config["algo"] == "oops-td3"]
    pwil = [r for r in runs if r.config["algo"] == "pwil-td3"]
    assert all(r.config["oops"]["reg"] == 0.1 for r in oops)
    assert all(r.config["oops"] is None for r in pwil)  # OOPS's settings skip PWIL's runs
    assert all(r.config["oops"]["seed"] == r.config["seed"] for r in oops)
    assert {r.config["num_demos"] for r in runs} == {1, 4}


def test_variants_merge_into_the_parts():
    spec = SweepSpec(
        config={**TINY, "oops": {"reg": 0.1}},
        variants={"l005": {"oops": {"reg": 0.005}}, "states": {"oops": {"atoms": "states"}}},
    )
    runs = {r.variant: r for r in expand(spec)}
    assert runs["l005"].name == "Hopper-v5__oops-td3__l005__demos1__0"
    assert runs["l005"].config["oops"]["reg"] == 0.005
    assert runs["states"].config["oops"] == {**runs["states"].config["oops"], "reg": 0.1}
    assert runs["states"].config["oops"]["atoms"] == "states"


def test_the_demos_apply_to_the_imitation_algos_of_a_sweep():
    # The true-reward algos refuse a demo file; a sweep comparing OOPS with its control keeps
    # one base config, as it does for the parts that only some of its algos use.
    runs = {r.config["algo"]: r for r in expand(SweepSpec(algo=("oops-td3", "td3"), config=TINY))}
    assert runs["oops-td3"].config["demos"] == TINY["demos"]
    assert runs["td3"].config["demos"] is None


def test_dropping_contact_forces_applies_to_the_envs_that_observe_them():
    spec = SweepSpec(env=("Hopper-v5", "Humanoid-v5"), config={**TINY, "contact_forces": False})
    spec = dataclasses.replace(spec, config={k: v for k, v in spec.config.items() if k != "demos"})
    runs = {r.config["env"]: r for r in expand(spec)}
    assert runs["Humanoid-v5"].config["contact_forces"] is False
    assert runs["Hopper-v5"].config["contact_forces"] is None
    unset = dataclasses.replace(spec, env=("Hopper-v5",), config={**TINY, "contact_forces": None})
    assert [r.config["contact_forces"] for r in expand(unset)] == [None]  # None is no setting
    default = dataclasses.replace(
        spec, config={k: v for k, v in spec.config.items() if k != "contact_forces"}
    )
    assert [r.config["contact_forces"] for r in expand(default)] == [None, None]


def test_a_finished_runs_config_json_as_the_spec_config_repeats_it_on_the_sweeps_axes(tmp_path):
    """A spec's config may name a run's config.json: its settings are kept, its env, algo,
    demos, seed and out are the sweep's, and its contact-force choice goes with its env."""
    from ilfo.training import TrainConfig

    recorded = TrainConfig(
        env="Humanoid-v5", seed=5, steps=123_000, preset="fast", contact_forces=True, out="x"
    ).resolved(horizon=1000)
    record = tmp_path / "config.json"
    raw = dataclasses.asdict(recorded)
    raw["td3"]["batch_size"] = 64  # a part's setting off its default
    record.write_text(json.dumps(raw))
    spec_file = {"env": ["Hopper-v5", "Ant-v5"], "seed": "0-1", "config": str(record)}
    runs = expand(SweepSpec.from_dict(spec_file))
    assert [(r.config["env"], r.config["seed"]) for r in runs] == [
        ("Hopper-v5", 0),
        ("Ant-v5", 0),
        ("Hopper-v5", 1),
        ("Ant-v5", 1),
    ]
    assert all(r.config["steps"] == 123_000 for r in runs)
    assert all(r.config["td3"]["batch_size"] == 64 for r in runs)
    assert all(r.config["td3"]["critic_hidden"] == [256, 256] for r in runs)  # the fast preset
    assert all(r.config["contact_forces"] is None for r in runs)  # each env's own default
    assert all(r.config["out"] != "x" for r in runs)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"config": {"seed": 3}}, "its axis"),
        ({"config": {"out": "x"}}, "sweep directory"),
        ({"seed": (0, 0)}, "twice"),
        ({"algo": ()}, "algo must hold at least 1 value"),
        ({"config": {"sac": {"tau": 0.01}}}, "no algo of the sweep uses"),
        ({"config": {"oops": {"nope": 1}}}, "no setting"),
        ({"config": {"steps": 0}}, "steps must be >= 1"),
        ({"variants": {"a__b": {}}}, "variant name"),
        ({"retries": -1}, "retries"),
        ({"config": {"contact_forces": False}}, "none of its envs observe"),
        ({"env": ("Hopper-v5", "Hoper-v5")}, "unknown environment 'Hoper-v5'"),
        ({"seed": (-3,)}, "seed must hold numbers that are >= 0"),
    ],
)
def test_bad_specs_are_refused_clearly(kwargs, message):
    with pytest.raises(ValueError, match=message):
        expand(SweepSpec(**kwargs))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"num_demos": 2.5}, "num_demos must be a list of integers, got 2.5 (float)"),
        ({"num_demos": (0, 1)}, "num_demos must hold numbers that are >= 1, got (0, 1)"),
        ({"seed": (0, 2**32)}, "seed must hold numbers that are >= 0 and at most 4,294,967,295"),
        ({"algo": ("td3", 3)}, "algo must be a list of strings, got ('td3', 3)"),
        ({"retries": 2**40}, "retries must be at most 2,147,483,647"),
        ({"retries": 1.5}, "retries must be an integer, got 1.5 (float)"),
    ],
)
def test_a_bad_axis_or_retries_is_refused_by_the_spec_itself(kwargs, message):
    """Declared ranges (ilfo.ranges): refused when the spec is made, before any run's config."""
    with pytest.raises(ValueError) as refused:
        SweepSpec(**kwargs)
    assert message in str(refused.value) and "\n" not in str(refused.value)
    with pytest.raises(ValueError, match=r"^spec\.json: "):  # a spec file's error names the file
        SweepSpec.from_dict(kwargs, "spec.json")


def test_a_spec_holds_its_axes_as_tuples_of_ints():
    import numpy as np

    spec = SweepSpec(num_demos=[np.int64(2)], seed=[np.int32(4), 5], retries=np.int64(1))
    assert spec.num_demos == (2,) and spec.seed == (4, 5) and spec.retries == 1
    assert {type(v) for v in (*spec.num_demos, *spec.seed, spec.retries)} == {int}


def test_parse_seeds():
    assert parse_seeds(["0-2", "7"]) == (0, 1, 2, 7)
    with pytest.raises(ValueError, match="reversed range"):
        parse_seeds(["3-1"])
    with pytest.raises(ValueError, match="neither a seed nor a range"):
        parse_seeds(["1-x"])
    with pytest.raises(ValueError, match="seeds are >= 0"):
        parse_seeds(["-3"])


def test_manifest_round_trip_and_a_different_spec_refused(tmp_path):
    spec = SweepSpec(
        algo=("oops-td3", "pwil-td3"), config={**TINY, "td3": {"critic_hidden": [64, 64]}}
    )
    sweep = create_sweep(tmp_path / "s", spec)
    again = open_sweep(tmp_path / "s")
    assert again.spec == spec and again.runs == sweep.runs
    assert create_sweep(tmp_path / "s", spec).runs == sweep.runs  # same spec: the same sweep
    more = dataclasses.replace(spec, retries=5)  # retries alone may change
    assert create_sweep(tmp_path / "s", more).runs == sweep.runs
    assert open_sweep(tmp_path / "s").spec.retries == 5
    with pytest.raises(ValueError, match="holds another sweep"):
        create_sweep(tmp_path / "s", SweepSpec(config=TINY))
    with pytest.raises(FileNotFoundError, match="not a sweep directory"):
        open_sweep(tmp_path)


def _finish(sweep, name, step=None):
    """What a finished run leaves: a complete checkpoint at its steps and the final policy."""
    run = sweep.run(name)
    ckpt = sweep.run_dir(name) / "checkpoints" / f"step_{step or run.steps}"
    ckpt.mkdir(parents=True)
    for file in (*CHECKPOINT_FILES, REPLAY_FILE):
        (ckpt / file).write_text("x")
    (sweep.run_dir(name) / FINAL_POLICY_FILE).write_text("x")


def test_run_states_read_off_the_disk(tmp_path):
    sweep = create_sweep(tmp_path, SweepSpec(seed=(0, 1, 2, 3), config=TINY, retries=1))
    a, b, c, d = (r.name for r in sweep.runs)
    _finish(sweep, a)
    _finish(sweep, d, step=200)  # a final policy, but short of its steps (a shortened run)
    (sweep.run_dir(b)).mkdir(parents=True)
    lock = RunLock(sweep.run_dir(b)).acquire()
    (sweep.run_dir(c)).mkdir(parents=True)
    (sweep.run_dir(c) / "metrics.csv").write_text("step,episode\n100,1\n200,2\n")
    for _ in range(2):
        record_attempt(sweep, c, "end", status="error", error="boom")
    states = {s.name: s for s in sweep.statuses()}
    assert states[a].state == "done"
    assert states[b].state == "running"
    assert states[c].state == "failed" and states[c].failures == 2 and states[c].error == "boom"
    assert states[c].step == 200
    assert states[d].state == "pending"
    assert states[b].steps_per_s is None  # running, but no episodes yet to time
    # A running run's speed over its recent rows (wall time in seconds), and its time left.
    rows = [
        "step,episode,wall_time,critic_loss,eval_score",
        "50,1,1.0,,",  # the random steps: no updates, far faster, not counted
        "100,2,10.0,0.3,",
        "200,3,12.0,0.2,0.5",
        "300,4,",
    ]
    (sweep.run_dir(b) / "metrics.csv").write_text("\n".join(rows))  # the last row half written
    running = run_status(sweep, sweep.run(b))
    assert running.steps_per_s == pytest.approx(50.0)
    assert running.hours_left == pytest.approx((running.steps - running.step) / 50 / 3600)
    assert states[c].steps_per_s is None and states[c].hours_left is None  # not running
    lock.release()
    assert run_status(sweep, sweep.run(b)).state == "pending"
    assert run_status(sweep, sweep.run(b)).steps_per_s is None
    record_attempt(sweep, c, "reset")
    assert run_status(sweep, sweep.run(c)).state == "pending"


def test_a_run_with_results_and_no_checkpoint_is_unresumable_not_trained_again(tmp_path, capsys):
    """A finished run whose checkpoints were removed (to free the disk) would start again from
    step 0, deleting its metrics and policy: it is reported as unresumable, says why, and is
    not started; one killed while writing its first checkpoint is pending, as before."""
    from ilfo.cli import main

    sweep = create_sweep(tmp_path, SweepSpec(seed=(0, 1), config=TINY))
    finished, killed = (r.name for r in sweep.runs)
    _finish(sweep, finished)
    rows = "step,episode\n100,1\n200,2\n300,3\n400,4\n"
    (sweep.run_dir(finished) / "metrics.csv").write_text(rows)
    shutil.rmtree(sweep.run_dir(finished) / "checkpoints")
    sweep.run_dir(killed).mkdir(parents=True)  # its first checkpoint falls due at step 200
    (sweep.run_dir(killed) / "metrics.csv").write_text("step,episode\n100,1\n200,2\n")
    states = {s.name: s for s in sweep.statuses()}
    assert states[killed].state == "pending"
    gone = states[finished]
    assert gone.state == "unresumable" and gone.step == 400 and gone.failures == 0
    assert str(sweep.run_dir(finished)) in gone.error
    assert "4 metrics rows to step 400" in gone.error and FINAL_POLICY_FILE in gone.error
    backend = _FakeBackend({killed: ["done"]})
    final = {s.name: s for s in run_sweep(sweep, backend, poll_seconds=0)}
    assert backend.started == [killed] and final[finished].state == "unresumable"
    assert (sweep.run_dir(finished) / "metrics.csv").read_text() == rows
    assert main(["sweep", "status", str(sweep.root)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:2] == [finished, "unresumable"] and "move the directory" in lines[0]
    assert lines[1].split()[:2] == [killed, "done"]
    assert "1 done, 0 running, 0 failed, 0 pending, 1 unresumable" in lines[2]


def test_snapshot_keeps_checkpoints_without_buffers_and_continues_as_a_sweep(tmp_path):
    sweep = create_sweep(tmp_path / "sweep", SweepSpec(seed=(0, 1, 2, 3), config=TINY))
    done, partial, unstarted, gone = (r.name for r in sweep.runs)
    _finish(sweep, done)
    _finish(sweep, gone)  # a finished run whose checkpoints were removed: unresumable
    (sweep.run_dir(gone) / "metrics.csv").write_text("step,episode\n100,1\n200,2\n300,3\n")
    shutil.rmtree(sweep.run_dir(gone) / "checkpoints")
    _finish(sweep, partial, step=200)
    (sweep.run_dir(partial) / FINAL_POLICY_FILE).unlink()  # interrupted at step 200
    for name in (done, partial):
        (sweep.run_dir(name) / CONFIG_FILE).write_text(json.dumps(sweep.run(name).config))
        (sweep.run_dir(name) / "metrics.csv").write_text("step,episode\n100,1\n200,2\n")
        record_attempt(sweep, name, "start")
    sweep.log_file(done).write_text("log")
    (sweep.run_dir(unstarted)).mkdir(parents=True)  # started, killed before a checkpoint
    lock = RunLock(sweep.run_dir(partial)).acquire()
    with pytest.raises(ValueError, match="running"):
        snapshot_sweep(sweep.root, tmp_path / "copy")
    lock.release()
    kept = snapshot_sweep(sweep.root, tmp_path / "copy")
    assert kept == {
        done: "done",
        partial: "checkpoint at step 200",
        unstarted: "left out (no checkpoint)",
        gone: "unresumable (results, no checkpoint)",
    }
    copy = open_sweep(tmp_path / "copy")
    assert copy.runs == sweep.runs
    assert [s.state for s in copy.statuses()] == ["done", "pending", "pending", "unresumable"]
    for name in ("metrics.csv", FINAL_POLICY_FILE):  # its results, not started again there
        assert (copy.run_dir(gone) / name).read_bytes() == (sweep.run_dir(gone) / name).read_bytes()
    assert copy.statuses()[1].step == 200
    assert read_attempts(copy, done) == read_attempts(sweep, done)
    assert copy.log_file(done).read_text() == "log"
    assert not list((tmp_path / "copy").rglob(REPLAY_FILE))
    assert (copy.run_dir(partial) / "checkpoints" / "step_200" / REPLAY_OMITTED).is_file()
    assert not copy.run_dir(unstarted).exists()
    with pytest.raises(FileExistsError):
        snapshot_sweep(sweep.root, tmp_path / "copy")
    with pytest.raises(ValueError, match="inside"):  # a copy into what it copies
        snapshot_sweep(sweep.root, sweep.root / "copy")
    assert not (sweep.root / "copy").exists()


class _FakeJob:
    def __init__(self, name, code):
        self.name, self.code = name, code

    def poll(self):
        return self.code

    def interrupt(self):
        pass


class _FakeBackend:
    """Jobs that end at once, as planned per run: 'done', 'error' (the worker says so), 'kill'
    (a SIGKILL: nothing recorded by the worker) or 'crash' (exit 1 before it could record its
    end, e.g. a full disk)."""

    slots = 2

    def __init__(self, plan):
        self.plan = plan
        self.started = []

    def start(self, sweep, name, slot):
        self.started.append(name)
        outcome = self.plan[name].pop(0)
        record_attempt(sweep, name, "start")
        if outcome == "done":
            _finish(sweep, name)
            record_attempt(sweep, name, "end", status="done")
            return _FakeJob(name, 0)
        if outcome == "error":
            record_attempt(sweep, name, "end", status="error", error="ValueError: boom")
            return _FakeJob(name, 1)
        if outcome == "crash":
            return _FakeJob(name, 1)
        return _FakeJob(name, -9)

    def watch(self, sweeps):
        self.watched = [sweep.root for sweep in sweeps]

    def close(self):
        pass


def test_scheduler_skips_retries_and_gives_up(tmp_path):
    sweep = create_sweep(tmp_path, SweepSpec(seed=(0, 1, 2, 3), config=TINY, retries=2))
    a, b, c, d = (r.name for r in sweep.runs)
    _finish(sweep, a)  # done before the sweep starts: skipped
    plan = {b: ["done"], c: ["error", "kill", "done"], d: ["error", "error", "error"]}
    backend = _FakeBackend(plan)
    final = {s.name: s for s in run_sweep(sweep, backend, poll_seconds=0)}
    assert backend.started.count(a) == 0
    assert backend.started.count(b) == 1
    assert backend.started.count(c) == 3 and final[c].state == "done"
    assert backend.started.count(d) == 3 and final[d].state == "failed"
    assert final[d].failures == 3 and "boom" in final[d].error
    killed = [e for e in read_attempts(sweep, c) if e.get("status") == "killed"]
    assert len(killed) == 1 and killed[0]["error"] == "worker exit -9"


def test_a_worker_that_fails_without_recording_counts_as_a_failure(tmp_path):
    """Exit 1 with no end record (it died before it could write one) is bounded by the retries,
    not requeued forever."""
    sweep = create_sweep(tmp_path, SweepSpec(config=TINY, retries=1))
    (run,) = (r.name for r in sweep.runs)
    backend = _FakeBackend({run: ["crash", "crash", "done"]})
    (final,) = run_sweep(sweep, backend, poll_seconds=0)
    assert backend.started == [run, run] and final.state == "failed" and final.failures == 2
    assert final.error == "worker exit 1"
    # Started again, nothing is left to do: no run starts twice.
    backend = _FakeBackend({})
    run_sweep(sweep, backend, poll_seconds=0)
    assert backend.started == []


def test_select_runs_by_pattern():
    names = [
        "Hopper-v5__oops-td3__demos1__0",
        "Hopper-v5__pwil-td3__demos1__0",
        "Ant-v5__oops-td3__demos1__0",
        "Ant-v5__pwil-td3__demos1__0",
    ]
    assert select_runs(names) == tuple(names)
    assert select_runs(names, only=["Ant-v5__*"]) == tuple(names[2:])
    assert select_runs(names, skip=["Ant-v5__*"]) == tuple(names[:2])
    assert select_runs(names, only=["*__pwil-td3__*"], skip=["Ant-v5__*"]) == (names[1],)
    assert select_runs(names, only=["Hopper-v5__*", "*__pwil-td3__*"]) == (
        names[0],
        names[1],
        names[3],
    )
    with pytest.raises(ValueError, match="no run matches 'Ant-v4__\\*'"):
        select_runs(names, skip=["Ant-v4__*"])  # a typo is an error, not "skip nothing"


def test_scheduler_runs_only_the_chosen_runs(tmp_path):
    sweep = create_sweep(tmp_path, SweepSpec(seed=(0, 1, 2), config=TINY))
    a, b, c = (r.name for r in sweep.runs)
    backend = _FakeBackend({a: ["done"], c: ["done"]})
    final = {s.name: s for s in run_sweep(sweep, backend, poll_seconds=0, names=[a, c])}
    assert backend.started == [a, c]
    assert final[b].state == "pending"  # reported, untouched
    backend = _FakeBackend({b: ["done"]})  # a later sweep without the choice runs the rest
    run_sweep(sweep, backend, poll_seconds=0)
    assert backend.started == [b]
    with pytest.raises(KeyError, match="no runs named"):
        run_sweep(sweep, _FakeBackend({}), poll_seconds=0, names=["nope"])


def test_thread_environment_and_pinning():
    env = thread_environment(2, [0])
    assert env["OPENBLAS_NUM_THREADS"] == env["OMP_NUM_THREADS"] == "2"
    before = os.sched_getaffinity(0)
    try:
        assert pin_from_environment({"ILFO_CPUS": "0"}) == [0]
        assert os.sched_getaffinity(0) == {0}
    finally:
        os.sched_setaffinity(0, before)
    with pytest.raises(ValueError):
        thread_environment(0)


def _sweep_cli(root, *extra):
    return [
        sys.executable, "-m", "ilfo.cli", "sweep", "run", str(root), "--no-progress",
        *extra,
    ]  # fmt: skip


@pytest.mark.integration
def test_killed_sweep_restarted_finishes_each_run_exactly_once(tmp_path):
    """A real local sweep of two tiny runs, SIGKILLed once a run has checkpointed: its workers
    checkpoint and stop with it, and the restarted sweep resumes them; every run ends with one
    metrics row per episode (nothing trained twice), pinned to a CPU of its own."""
    root = tmp_path / "sweep"
    flags = [f"--{k.replace('_', '-')}={v}" for k, v in {**TINY, "steps": 600}.items()]
    cmd = _sweep_cli(root, "--seeds", "0", "1", *flags)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        if list(root.glob("runs/*/checkpoints/step_*/state.json")):
            break
        time.sleep(0.2)
    assert proc.poll() is None, proc.stdout.read().decode()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    sweep = open_sweep(root)
    deadline = time.monotonic() + 120  # the workers checkpoint and exit on their own
    while time.monotonic() < deadline and any(s.state == "running" for s in sweep.statuses()):
        time.sleep(0.2)
    assert not any(s.state == "done" for s in sweep.statuses())
    newest = {
        run.name: max(int(d.name.removeprefix("step_")) for d in checkpoints)
        for run in sweep.runs
        if (checkpoints := list(sweep.run_dir(run.name).glob("checkpoints/step_*")))
    }
    assert newest and all(step > 0 for step in newest.values())
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    statuses = sweep.statuses()
    assert [s.state for s in statuses] == ["done", "done"]
    assert sorted(p.name for p in (root / "runs").iterdir()) == sorted(r.name for r in sweep.runs)
    cpus = []
    for run in sweep.runs:
        rows = (sweep.run_dir(run.name) / "metrics.csv").read_text().splitlines()[1:]
        steps = [int(row.split(",")[0]) for row in rows]
        assert steps == sorted(set(steps)) and steps[-1] == 600  # each episode logged once
        if run.name in newest:  # resumed from its checkpoint, not trained again from step 0
            log = sweep.log_file(run.name).read_text()
            assert f"training to step 600 from {newest[run.name]:,}" in log, log
        events = read_attempts(sweep, run.name)
        ends = [e["status"] for e in events if e["event"] == "end"]
        assert ends[-1] == "done" and ends.count("done") == 1 and "error" not in ends
        starts = [e for e in events if e["event"] == "start"]
        assert all(len(e["cpus"]) == 1 and e["threads"]["OPENBLAS_NUM_THREADS"] == "1"
                   for e in starts)  # fmt: skip
        cpus.append(starts[-1]["cpus"][0])
    if len(os.sched_getaffinity(0)) >= 2:
        assert len(set(cpus)) == 2  # the two runs side by side on CPUs of their own
    status = subprocess.run(
        [sys.executable, "-m", "ilfo.cli", "sweep", "status", str(root), "--json"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert [json.loads(line)["state"] for line in status.stdout.splitlines()] == ["done"] * 2


@pytest.mark.slow
def test_ray_backend_runs_a_tiny_sweep(tmp_path):
    """A local Ray instance (2 CPUs) runs the sweep's runs as tasks, each one thread."""
    ray = pytest.importorskip("ray")
    from ilfo.experiments import RayBackend

    sweep = create_sweep(tmp_path, SweepSpec(algo=("oops-td3", "pwil-td3"), config=TINY))
    backend = RayBackend(num_cpus=2, cores_per_run=1)
    assert backend.slots == 2
    final = run_sweep(sweep, backend, poll_seconds=0.5)
    assert [s.state for s in final] == ["done", "done"]
    assert not ray.is_initialized()  # the backend shut down the instance it started
    for run in sweep.runs:
        starts = [e for e in read_attempts(sweep, run.name) if e["event"] == "start"]
        assert len(starts) == 1 and starts[0]["threads"]["OPENBLAS_NUM_THREADS"] == "1"
        assert "intra_op_parallelism_threads=1" in starts[0]["threads"]["XLA_FLAGS"]


def test_cli_dry_run_shows_what_only_and_skip_leave_out(tmp_path, capsys):
    from ilfo.cli import main

    axes = ["--env", "Hopper-v5", "Walker2d-v5", "--algo", "oops-td3", "pwil-td3"]
    root = str(tmp_path / "sweep")
    assert main(["sweep", "run", root, *axes, "--skip", "Walker2d-v5__*", "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines == [
        "Hopper-v5__oops-td3__demos1__0",
        "Hopper-v5__pwil-td3__demos1__0",
        "Walker2d-v5__oops-td3__demos1__0  (left out)",
        "Walker2d-v5__pwil-td3__demos1__0  (left out)",
    ]
    assert main(["sweep", "run", root, *axes, "--only", "Hoper-v5__*", "--dry-run"]) != 0
    assert "no run matches 'Hoper-v5__*'" in capsys.readouterr().err
    fresh = tmp_path / "fresh"
    assert main(["sweep", "run", str(fresh), *axes, "--skip", "Hoper-v5__*"]) != 0
    assert not fresh.exists()  # refused before the sweep directory is made
    for flag in ("--workers", "--cores-per-run"):
        assert main(["sweep", "run", str(fresh), *axes, flag, "0"]) != 0
        assert not fresh.exists()
        assert main(["sweep", "run", str(fresh), *axes, "--backend", "ray", flag, "0"]) != 0
        assert not fresh.exists()
    cluster = ["--backend", "ray", "--address", "auto", "--workers", "2"]  # its CPUs decide
    assert main(["sweep", "run", str(fresh), *axes, *cluster]) == 2
    assert "a cluster (--address) runs as many as its CPUs hold" in capsys.readouterr().err


def test_cli_dry_run_on_an_existing_sweep_checks_the_spec_as_the_run_would(tmp_path, capsys):
    from ilfo.cli import main

    root = tmp_path / "sweep"
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps(SweepSpec(env=("Hopper-v5",), config=TINY).to_dict()))
    assert main(["sweep", "run", str(root), "--spec", str(spec_file), "--dry-run"]) == 0
    assert not root.exists()
    create_sweep(root, SweepSpec(env=("Hopper-v5",), config=TINY))
    # Another axis: the dry run refuses what the real command would refuse, and writes nothing.
    more = ["--spec", str(spec_file), "--seeds", "0-1", "--dry-run"]
    assert main(["sweep", "run", str(root), *more]) != 0
    assert "holds another sweep" in capsys.readouterr().err
    assert open_sweep(root).spec.seed == (0,)
    # The same spec, or none: the sweep as it is, with each run's state.
    for given in (["--spec", str(spec_file)], []):
        assert main(["sweep", "run", str(root), *given, "--dry-run"]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert lines == ["Hopper-v5__oops-td3__demos1__0  pending"]


def test_cli_retries_alone_and_part_flags_over_a_spec_file(tmp_path, capsys):
    """`--retries N` alone changes an existing sweep's retries (it was read as a new default
    spec and refused); a part flag changes its one field of the spec file's part."""
    from ilfo.cli import main

    root = tmp_path / "sweep"
    sweep = create_sweep(root, SweepSpec(config=TINY))
    _finish(sweep, sweep.runs[0].name)
    assert main(["sweep", "run", str(root), "--retries", "4", "--no-progress"]) == 0
    assert open_sweep(root).spec.retries == 4
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps({"config": {**TINY, "td3": {"batch_size": 64}}}))
    merged = create_sweep(
        tmp_path / "merged", SweepSpec(config={**TINY, "td3": {"batch_size": 64, "tau": 0.01}})
    )
    given = ["--spec", str(spec_file), "--td3-tau", "0.01", "--dry-run"]
    assert main(["sweep", "run", str(merged.root), *given]) == 0  # the same spec: batch_size kept
    assert "holds another sweep" not in capsys.readouterr().err


@pytest.mark.integration
@pytest.mark.skipif(
    not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
    reason="needs two CPUs to choose between",
)
def test_local_workers_pass_over_cpus_another_process_holds(tmp_path):
    """Two `sweep run` processes on one sweep (disjoint --only): the second's first worker
    takes a CPU the first's live worker is not pinned to."""
    from ilfo.experiments.backends import LocalBackend

    sweep = create_sweep(tmp_path, SweepSpec(seed=(0, 1), config=TINY))
    first, second = (r.name for r in sweep.runs)
    cpus = sorted(os.sched_getaffinity(0))
    backend = LocalBackend(workers=1)
    assert backend.cpu_set(sweep, 0) == cpus[:1]  # nothing held: the slot's own share
    record_attempt(sweep, first, "start", pid=os.getpid(), cpus=cpus[:1])  # a live worker
    assert backend.cpu_set(sweep, 0) == cpus[1:2]
    record_attempt(sweep, first, "end", status="interrupted")  # it stopped: free again
    assert backend.cpu_set(sweep, 0) == cpus[:1]
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout  # fmt: skip
    record_attempt(sweep, second, "start", pid=int(dead), cpus=cpus[:1])  # killed, no end
    assert backend.cpu_set(sweep, 0) == cpus[:1]
    all_held = LocalBackend(workers=len(cpus))
    record_attempt(sweep, second, "start", pid=os.getpid(), cpus=cpus)
    assert all_held.cpu_set(sweep, 1) == cpus[1:2]  # too few free: the slot's own share
    # Another process holds every CPU but slot 1's share, which slot 0 takes: slot 1 shares
    # a CPU of the other process's (free once its worker ends), not its own slot 0's.
    from types import SimpleNamespace

    two = LocalBackend(workers=2)
    record_attempt(sweep, second, "start", pid=os.getpid(), cpus=[cpus[0], *cpus[2:]])
    assert two.cpu_set(sweep, 0) == cpus[1:2]
    live = SimpleNamespace(poll=lambda: None, process=SimpleNamespace(pid=-1))
    two._jobs[0] = live  # type: ignore[assignment]
    assert two.cpu_set(sweep, 1) == cpus[:1]


def test_local_workers_pass_over_cpus_held_on_another_watched_sweep(tmp_path):
    """Another process's live worker on a sweep whose runs this one has not started yet (all
    held elsewhere) still keeps this one's first worker off its CPU, once the sweep is
    watched."""
    from ilfo.experiments.backends import LocalBackend

    one, two = (create_sweep(tmp_path / d, SweepSpec(config=TINY)) for d in ("one", "two"))
    (name,) = (r.name for r in one.runs)
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        pytest.skip("needs two usable CPUs (a process pinned to one has nowhere to pass to)")
    record_attempt(one, name, "start", pid=os.getpid(), cpus=cpus[:1])  # live, elsewhere
    backend = LocalBackend(workers=1)
    assert backend.cpu_set(two, 0) == cpus[:1]  # sweep one not watched: not seen
    backend.watch([one, two])
    assert backend.cpu_set(two, 0) == cpus[1:2]


def test_a_queued_run_another_process_started_is_waited_for_not_started(tmp_path):
    """The queue is read at the start; a run that another `sweep run` process starts meanwhile
    is checked again before its start, waited for, and never started here."""
    sweep = create_sweep(tmp_path, SweepSpec(seed=(0, 1), config=TINY))
    a, b = (r.name for r in sweep.runs)
    sweep.run_dir(b).mkdir(parents=True)
    other_process = RunLock(sweep.run_dir(b))

    class OneSlot(_FakeBackend):
        slots = 1

        def start(self, sweep, name, slot):
            if name == a:
                other_process.acquire()  # meanwhile, elsewhere, b starts
            return super().start(sweep, name, slot)

    def on_change(statuses, message):
        if {s.name: s.state for s in statuses}.get(b) == "running":
            _finish(sweep, b)  # the other process finishes b
            other_process.release()

    backend = OneSlot({a: ["done"], b: ["done"]})
    final = {s.name: s for s in run_sweep(sweep, backend, poll_seconds=0, on_change=on_change)}
    assert backend.started == [a] and final[b].state == "done"


class _SlowJob(_FakeJob):
    """A run that finishes at its ``polls``-th poll."""

    def __init__(self, sweep, name, polls):
        super().__init__(name, None)
        self.sweep, self.polls = sweep, polls

    def poll(self):
        self.polls -= 1
        if self.polls == 0:
            _finish(self.sweep, self.name)
            record_attempt(self.sweep, self.name, "end", status="done")
            self.code = 0
        return self.code


def test_sweeps_run_as_one_queue_so_a_free_slot_takes_the_next_sweeps_runs(tmp_path):
    """Two sweeps (the same runs' names in each) on two slots: the second sweep's run starts
    beside the first's last run, not after it ends; each run once, messages name the sweep."""
    one, two = (create_sweep(tmp_path / d, SweepSpec(config=TINY)) for d in ("one", "two"))
    (name,) = (r.name for r in one.runs)
    started = []

    class Backend(_FakeBackend):
        def start(self, sweep, name, slot):
            started.append((sweep.root.name, slot, [job.code for job in jobs]))
            record_attempt(sweep, name, "start")
            jobs.append(_SlowJob(sweep, name, polls=3))
            return jobs[-1]

    jobs = []
    messages = []
    final = run_sweeps(
        [one, two], Backend({}), poll_seconds=0, on_change=lambda s, m: messages.append(m)
    )
    # the second sweep's run started in the other slot while the first's had not ended
    assert started == [("one", 0, []), ("two", 1, [None])]
    assert [(s.name, s.state) for s in final] == [(name, "done"), (name, "done")]
    assert f"started one/{name}" in messages and f"two/{name}: done" in messages


def test_a_run_held_elsewhere_does_not_hold_up_the_next_sweep(tmp_path):
    """One slot; the first sweep's only pending run is trained by another process: the
    second sweep's run starts meanwhile, and the held run is waited for: when the other
    process lets it go unfinished, it is started here."""
    one, two = (create_sweep(tmp_path / d, SweepSpec(config=TINY)) for d in ("one", "two"))
    (name,) = (r.name for r in one.runs)
    one.run_dir(name).mkdir(parents=True)
    other_process = RunLock(one.run_dir(name)).acquire()
    held_when_started = []
    calls = []

    class OneSlot(_FakeBackend):
        slots = 1

        def start(self, sweep, name, slot):
            held_when_started.append((sweep.root.name, other_process.held))
            return super().start(sweep, name, slot)

    def on_change(statuses, message):
        calls.append(message)
        assert len(calls) < 10_000, "the scheduler waits on the held run alone"
        if calls[-6:-5] == [f"two/{name}: done"]:  # five polls on, with nothing else to run,
            other_process.release()  # the other process stops, its run unfinished

    backend = OneSlot({name: ["done", "done"]})
    final = run_sweeps([one, two], backend, poll_seconds=0, on_change=on_change)
    assert held_when_started == [("two", True), ("one", False)]
    assert [s.state for s in final] == ["done", "done"]
    assert backend.watched == [one.root, two.root]


def test_a_retried_run_goes_before_later_sweeps_runs(tmp_path):
    """A run that failed within its retries rejoins the queue after its own sweep's runs and
    before the next sweep's, as when each sweep ran in turn."""
    one = create_sweep(tmp_path / "one", SweepSpec(seed=(0, 1), config=TINY, retries=1))
    two = create_sweep(tmp_path / "two", SweepSpec(seed=(5,), config=TINY))
    a, b = (r.name for r in one.runs)
    (c,) = (r.name for r in two.runs)

    class OneSlot(_FakeBackend):
        slots = 1

    backend = OneSlot({a: ["error", "done"], b: ["done"], c: ["done"]})
    final = run_sweeps([one, two], backend, poll_seconds=0)
    assert backend.started == [a, b, a, c]
    assert [s.state for s in final] == ["done", "done", "done"]
    with pytest.raises(ValueError, match="given twice"):
        run_sweeps([one, open_sweep(tmp_path / "one")], backend, poll_seconds=0)


def test_run_sweeps_limits_each_sweep_to_its_names(tmp_path):
    """The same run names in two sweeps: each sweep runs its own chosen ones only."""
    one = create_sweep(tmp_path / "one", SweepSpec(seed=(0, 1), config=TINY))
    two = create_sweep(tmp_path / "two", SweepSpec(seed=(0, 1), config={**TINY, "steps": 600}))
    a, b = (r.name for r in one.runs)
    assert [r.name for r in two.runs] == [a, b]
    backend = _FakeBackend({a: ["done"], b: ["done"]})
    final = run_sweeps([one, two], backend, poll_seconds=0, names=[[a], [b]])
    assert backend.started == [a, b]
    assert [s.state for s in final] == ["done", "pending", "pending", "done"]
    with pytest.raises(KeyError, match="no runs named"):
        run_sweeps([one, two], backend, poll_seconds=0, names=[[a], ["nope"]])
    for wrong in ([[a]], [a, b]):  # one collection short; names, not collections
        with pytest.raises(ValueError, match="one collection of run names per sweep"):
            run_sweeps([one, two], backend, poll_seconds=0, names=wrong)


def test_sweep_labels_are_directory_names_or_paths_where_two_share_one(tmp_path):
    from ilfo.experiments import sweep_labels

    sweeps = [
        create_sweep(tmp_path / d, SweepSpec(config=TINY)) for d in ("x/sweep", "y/sweep", "z")
    ]
    assert sweep_labels(sweeps) == [str(tmp_path / "x/sweep"), str(tmp_path / "y/sweep"), "z"]
    here = open_sweep(Path(os.path.relpath(sweeps[2].root)))
    assert sweep_labels([here, sweeps[0]]) == ["z", "sweep"]


def test_cli_continues_several_sweeps_as_one_queue(tmp_path, monkeypatch, capsys):
    """`ilfo sweep run A B`: both sweeps' runs through one scheduler and backend, in order;
    --only/--skip, --retry-failed, --dry-run and the exit status cover both, and so does
    `ilfo sweep status A B`."""
    from ilfo.cli import main

    one = create_sweep(tmp_path / "one", SweepSpec(seed=(0, 1), config=TINY))
    two = create_sweep(tmp_path / "two", SweepSpec(seed=(5, 6), config=TINY, retries=0))
    a, b = (r.name for r in one.runs)
    c, d = (r.name for r in two.runs)
    _finish(one, a)
    backend = _FakeBackend({b: ["done"], c: ["error", "done"], d: ["done"]})
    backend.slots = 1
    monkeypatch.setattr("ilfo.cli.experiments._backend_factory", lambda args: lambda: backend)
    dirs = [str(one.root), str(two.root)]
    assert main(["sweep", "run", *dirs, "--skip", "*__6", "--dry-run"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"one/{a}  done",
        f"one/{b}  pending",
        f"two/{c}  pending",
        f"two/{d}  pending  (left out)",
    ]
    assert backend.started == []
    # c fails and is given up (no retries): the command says so and fails
    assert main(["sweep", "run", *dirs, "--skip", "*__6", "--no-progress"]) == 1
    out = capsys.readouterr().out
    assert backend.started == [b, c]
    assert backend.watched == [one.root, two.root]  # one queue over both, not one per sweep
    assert f"sweep {two.root}: 2 runs" in out and "running 1 of them" in out
    assert f"failed: {c}: ValueError: boom" in out
    assert main(["sweep", "status", *dirs]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[:2] for line in lines[:4]] == [
        [f"one/{a}", "done"],
        [f"one/{b}", "done"],
        [f"two/{c}", "failed"],
        [f"two/{d}", "pending"],
    ]
    assert "2 done, 0 running, 1 failed, 1 pending" in lines[4]  # one bar over both
    assert main(["sweep", "status", *dirs, "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [(r["sweep"], r["name"]) for r in rows] == [
        (str(one.root), a),
        (str(one.root), b),
        (str(two.root), c),
        (str(two.root), d),
    ]
    # --retry-failed forgets the failures of the runs it runs, not of those left out (whose
    # failure still fails the command)
    assert main(["sweep", "run", *dirs, "--retry-failed", "--only", "*__6", "--no-progress"]) == 1
    assert backend.started == [b, c, d]
    assert f"failed: {c}" in capsys.readouterr().out
    assert main(["sweep", "run", *dirs, "--retry-failed", "--no-progress"]) == 0
    assert backend.started == [b, c, d, c]
    assert all(s.state == "done" for sweep in (one, two) for s in sweep.statuses())


def test_cli_refuses_to_change_several_sweeps_at_once(tmp_path, capsys):
    from ilfo.cli import main

    one, two = (create_sweep(tmp_path / d, SweepSpec(config=TINY)) for d in ("one", "two"))
    dirs = [str(one.root), str(two.root)]
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps(one.spec.to_dict()))
    changes = (
        ["--steps", "400"],
        ["--seeds", "0-2"],
        ["--retries", "3"],
        ["--spec", str(spec_file)],
    )
    for change in changes:
        assert main(["sweep", "run", *dirs, *change, "--dry-run"]) == 2
        assert "give one DIR" in capsys.readouterr().err
    assert main(["sweep", "run", dirs[0], dirs[0] + "/", "--dry-run"]) == 2
    assert "given twice" in capsys.readouterr().err
    assert main(["sweep", "run", *dirs, str(tmp_path / "none"), "--dry-run"]) == 2
    assert "is not a sweep directory" in capsys.readouterr().err
    assert main(["sweep", "run", *dirs, "--only", "Walker2d-v5__*", "--dry-run"]) == 2
    assert "no run matches 'Walker2d-v5__*'" in capsys.readouterr().err
    assert main(["sweep", "run", dirs[0], "--dry-run", dirs[1]]) == 2  # a DIR after the flags
    assert "the sweep directories go first" in capsys.readouterr().err
    assert main(["sweep", "status", dirs[0], dirs[0]]) == 2
    assert "given twice" in capsys.readouterr().err
    assert open_sweep(one.root).spec == one.spec and not (tmp_path / "none").exists()


def test_a_worker_finding_its_run_held_elsewhere_exits_busy_not_failed(tmp_path):
    from ilfo.experiments.worker import EXIT_BUSY, main

    sweep = create_sweep(tmp_path, SweepSpec(config=TINY, retries=0))
    (run,) = (r.name for r in sweep.runs)
    sweep.run_dir(run).mkdir(parents=True)
    lock = RunLock(sweep.run_dir(run)).acquire()
    try:
        assert main([str(sweep.root), run]) == EXIT_BUSY
    finally:
        lock.release()
    assert read_attempts(sweep, run)[-1]["status"] == "busy"
    status = run_status(sweep, sweep.run(run))
    assert status.state == "pending" and status.failures == 0


def test_a_run_cut_short_by_hand_is_trained_to_the_manifests_budget(tmp_path, monkeypatch):
    """`ilfo train --resume RUN --steps 200` on a sweep's 400-step run wrote 200 to its
    config.json: the worker resumes it to the manifest's 400 (else it would end below its
    budget at every start, never done), and never below a budget raised by hand."""
    from types import SimpleNamespace

    from ilfo.experiments.worker import train_run
    from ilfo.training import Trainer

    asked = []

    def resume(run_dir, *, progress=True, steps=None, hooks=None):
        asked.append(steps)
        return SimpleNamespace(config=SimpleNamespace(steps=steps or 0), step=0, last_eval=None,
                               train=lambda: None)  # fmt: skip

    monkeypatch.setattr(Trainer, "resume", resume)
    sweep = create_sweep(tmp_path, SweepSpec(config=TINY))
    (run,) = sweep.runs
    sweep.run_dir(run.name).mkdir(parents=True)
    for written in (200, 800):
        (sweep.run_dir(run.name) / "config.json").write_text(json.dumps({"steps": written}))
        train_run(sweep.run_dir(run.name), run.config)
    assert asked == [400, None]  # 800: its own budget, as written
    # Killed after its last checkpoint, whose last episode went past the budget (step 412),
    # before its final policy: resumed as written, not with the checkpoint's step as a budget.
    from ilfo.training.run_dir import CHECKPOINT_FILES, REPLAY_FILE

    checkpoint = sweep.run_dir(run.name) / "checkpoints" / "step_00000412"
    checkpoint.mkdir(parents=True)
    for name in (*CHECKPOINT_FILES, REPLAY_FILE):
        (checkpoint / name).write_text("{}")
    (sweep.run_dir(run.name) / "config.json").write_text(json.dumps({"steps": 400}))
    train_run(sweep.run_dir(run.name), run.config)
    assert asked[-1] is None


def test_an_attempt_record_after_a_torn_line_is_kept(tmp_path):
    sweep = create_sweep(tmp_path, SweepSpec(config=TINY))
    (run,) = (r.name for r in sweep.runs)
    record_attempt(sweep, run, "start", pid=1)
    with sweep.attempts_file(run).open("a") as f:
        f.write('{"event": "en')  # a kill mid-write
    record_attempt(sweep, run, "end", status="killed")
    assert [e["event"] for e in read_attempts(sweep, run)] == ["start", "end"]


def test_cli_create_writes_a_sweep_to_queue_behind_others_without_running_it(
    tmp_path, monkeypatch, capsys
):
    """`ilfo sweep create`: the manifest `sweep run` would write, no run started; the same
    sweep again is left as it is, another refused, and `sweep run A NEW` queues it."""
    from ilfo.cli import main

    def no_backend(args):
        raise AssertionError("create made a backend")

    monkeypatch.setattr("ilfo.cli.experiments._backend_factory", no_backend)
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps({"env": ["Hopper-v5"], "seed": "0-1", "config": TINY}))
    root = tmp_path / "new"
    given = ["--spec", str(spec_file), "--td3-tau", "0.01"]
    assert main(["sweep", "create", str(root), *given]) == 0
    names = ["Hopper-v5__oops-td3__demos1__0", "Hopper-v5__oops-td3__demos1__1"]
    assert capsys.readouterr().out.splitlines() == [
        f"sweep {root}: 2 runs",
        *(f"{name}  pending" for name in names),
        f"run it: ilfo sweep run {root}; or queue it: ilfo sweep run OTHER... {root}",
    ]
    created = open_sweep(root)
    expected = SweepSpec(env=("Hopper-v5",), seed=(0, 1), config={**TINY, "td3": {"tau": 0.01}})
    assert created.spec == expected and [r.name for r in created.runs] == names
    assert created.runs[0].config["td3"]["tau"] == 0.01
    assert not any((root / "runs").iterdir()) and not any((root / "attempts").iterdir())
    # The same sweep: left as it is; --retries changes its retries, and they stay changed
    # when the sweep is given again without it.
    assert main(["sweep", "create", str(root), *given, "--retries", "5"]) == 0
    assert "2 runs (there already; retries 2 -> 5)" in capsys.readouterr().out
    assert main(["sweep", "create", str(root), *given]) == 0
    assert "2 runs (there already)" in capsys.readouterr().out
    assert open_sweep(root).spec == dataclasses.replace(expected, retries=5)
    assert main(["sweep", "create", str(root), "--retries", "6"]) == 0  # alone: this sweep's
    assert open_sweep(root).spec == dataclasses.replace(expected, retries=6)
    # Another sweep there: refused, the manifest unchanged.
    assert main(["sweep", "create", str(root), *given, "--seeds", "0-2"]) == 2
    assert "holds another sweep" in capsys.readouterr().err
    assert open_sweep(root).spec == dataclasses.replace(expected, retries=6)
    # Refused, with nothing made: nothing to create, --retries alone, a second DIR, a bad
    # train flag (argparse's exit), a folder of other files, a file.
    fresh = tmp_path / "fresh"
    refusals = {
        (): "nothing to create",
        ("--retries", "3"): "--retries alone changes an existing sweep",
        ("other", "--spec", str(spec_file)): "ilfo sweep create takes one DIR",
    }
    for bad, message in refusals.items():
        assert main(["sweep", "create", str(fresh), *bad]) == 2
        assert message in capsys.readouterr().err
        assert not fresh.exists()
    with pytest.raises(SystemExit) as exit_:
        main(["sweep", "create", str(fresh), "--env", "Hopper-v5", "--td3-tau", "x"])
    assert exit_.value.code == 2 and not fresh.exists()
    assert "invalid float value: 'x'" in capsys.readouterr().err
    fresh.mkdir()
    (fresh / "notes.txt").write_text("mine")
    assert main(["sweep", "create", str(fresh), *given]) == 2
    assert "holds other files and no sweep (notes.txt)" in capsys.readouterr().err
    assert sorted(p.name for p in fresh.iterdir()) == ["notes.txt"]
    assert main(["sweep", "create", str(fresh / "notes.txt"), *given]) == 2
    assert "is a file, not a sweep directory" in capsys.readouterr().err
    # Queued behind another sweep: one queue, in order.
    first = create_sweep(tmp_path / "first", SweepSpec(seed=(7,), config=TINY))
    backend = _FakeBackend({first.runs[0].name: ["done"], names[0]: ["done"], names[1]: ["done"]})
    backend.slots = 1
    monkeypatch.setattr("ilfo.cli.experiments._backend_factory", lambda args: lambda: backend)
    assert main(["sweep", "run", str(first.root), str(root), "--no-progress"]) == 0
    assert backend.started == [first.runs[0].name, *names]
