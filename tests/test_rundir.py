"""Run directories under failure: unique names, one owner, resume after a kill at any moment,
and a clear error (naming the file) for every damaged file a run reads."""

import errno
import json
import os
import shutil
import struct
import subprocess
import sys
import threading
import warnings

import jax
import numpy as np
import pytest

from ilfo import demos
from ilfo.cli import main
from ilfo.training import TrainConfig, Trainer
from ilfo.training.checkpoint import snapshot_run
from ilfo.training.run_dir import (
    FAULT_ENV,
    RunDirInUse,
    RunLock,
    create_run_dir,
    latest_checkpoint,
    results_past_first_checkpoint,
)
from tiny_run import DEMOS, metrics_rows, train_tiny
from tiny_run import TINY_RUN as TINY_RUN


def _cli_args(out, steps=600, **extra):
    args = ["train", "--no-progress", "--out", str(out), "--steps", str(steps)]
    for key, value in {**TINY_RUN, **extra}.items():
        args += [f"--{key.replace('_', '-')}", str(value)]
    return args


# ------------------------------------------------------------------- unique, owned directories
def test_run_dirs_created_at_the_same_moment_are_distinct(tmp_path):
    made, barrier = [], threading.Barrier(8)

    def create():
        barrier.wait()
        made.append(create_run_dir(tmp_path, "Hopper-v5__oops-td3__0__20261201-120000"))

    threads = [threading.Thread(target=create) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(made)) == 8 and all(p.is_dir() for p in made)
    assert sorted(p.name for p in made)[:2] == [
        "Hopper-v5__oops-td3__0__20261201-120000",
        "Hopper-v5__oops-td3__0__20261201-120000-2",
    ]


def test_cli_runs_started_in_the_same_second_write_their_own_directories(tmp_path, monkeypatch):
    import ilfo.training

    monkeypatch.setattr(ilfo.training, "run_name", lambda config: "same-name")
    assert main(_cli_args(tmp_path, steps=200)) == 0
    assert main(_cli_args(tmp_path, steps=200, oops_reg=0.1)) == 0
    first, second = tmp_path / "same-name", tmp_path / "same-name-2"
    assert [int(r["step"]) for r in metrics_rows(first)] == [100, 200]
    assert [int(r["step"]) for r in metrics_rows(second)] == [100, 200]
    assert json.loads((second / "config.json").read_text())["oops"]["reg"] == 0.1
    assert json.loads((first / "config.json").read_text())["oops"]["reg"] == 0.05


@pytest.mark.integration
def test_a_run_refuses_a_directory_another_process_writes(tmp_path):
    run = train_tiny(tmp_path, "run", steps=200)
    before = (run / "config.json").read_bytes(), metrics_rows(run)
    with RunLock(run):  # as another process resuming it would hold it
        with pytest.raises(RunDirInUse, match="in use by another run"):
            Trainer.resume(run, progress=False, steps=400)
        config = TrainConfig(**{**TINY_RUN, "steps": 200})
        with pytest.raises(RunDirInUse):
            Trainer(config, run, progress=False).train()
    assert ((run / "config.json").read_bytes(), metrics_rows(run)) == before
    # Unlocked, a fresh run still may not write into a directory that holds a run.
    with pytest.raises(ValueError, match="holds a run already"):
        Trainer(TrainConfig(**{**TINY_RUN, "steps": 200}), run, progress=False).train()
    assert Trainer.resume(run, progress=False, steps=300).train() == run  # the lock was freed


# ----------------------------------------------------------------------------------- resume
@pytest.mark.integration
def test_resume_finds_the_newest_complete_checkpoint_and_removes_leftovers(tmp_path):
    full = metrics_rows(train_tiny(tmp_path, "full", steps=400))
    run = train_tiny(tmp_path, "run", steps=300, checkpoint_every=100)
    root = run / "checkpoints"
    assert [p.name for p in root.iterdir()] == ["step_000000300"]  # older ones removed
    # What kills at other moments leave: a half-written checkpoint, an older checkpoint not yet
    # removed, and an incomplete directory (an older ilfo's stale pointer: test_compat).
    (root / ".tmp_step_000000400").mkdir()
    (root / ".tmp_step_000000400" / "agent.msgpack").write_bytes(b"\x00" * 10)
    (root / "step_000000200").mkdir()  # an older one whose removal was cut short
    (root / "step_000000200" / "replay.npz").write_bytes(b"\x00" * 10)
    assert latest_checkpoint(run).name == "step_000000300"
    trainer = Trainer.resume(run, progress=False, steps=400)
    assert trainer.step == 300
    assert not (root / ".tmp_step_000000400").exists()
    assert not (root / "step_000000200").exists()
    assert metrics_rows(trainer.train()) == full


@pytest.mark.integration
def test_a_newest_checkpoint_missing_files_is_refused_with_the_repair_not_skipped(tmp_path):
    """Checkpoints are renamed into place once written, so a newest one missing a file had it
    removed (replay.npz, to free disk): resuming from an older one or from step 0 would drop
    the steps and metrics logged since. Resume and snapshot say what is missing and how to go on."""
    full = metrics_rows(train_tiny(tmp_path, "full", steps=400))
    run = train_tiny(tmp_path, "run", steps=300, checkpoint_every=100)
    newest = run / "checkpoints" / "step_000000300"
    (newest / "replay.npz").unlink()
    rows = metrics_rows(run)
    for attempt in (
        lambda: Trainer.resume(run, progress=False, steps=400),
        lambda: snapshot_run(run, tmp_path / "snap"),
    ):
        with pytest.raises(FileNotFoundError, match=r"has no replay.npz .*touch .*replay.omitted"):
            attempt()
    assert metrics_rows(run) == rows and not (tmp_path / "snap").exists()  # nothing changed
    (newest / "replay.omitted").write_text("{}")  # the repair the message gives
    with pytest.warns(UserWarning, match="buffer is refilled"):
        trainer = Trainer.resume(run, progress=False, steps=400)
    assert trainer.step == 300 and [r["step"] for r in metrics_rows(trainer.train())] == [
        r["step"] for r in full
    ]
    (run / "checkpoints" / "step_000000400" / "state.json").unlink()
    with pytest.raises(FileNotFoundError, match=r"lacks state.json.*delete the directory"):
        Trainer.resume(run, progress=False, steps=500)


class _Killed(Exception):
    """Stands for a kill: the trainer stops where it is raised, writing nothing more."""


def _killed() -> None:
    raise _Killed


@pytest.mark.integration
def test_a_run_killed_before_its_first_checkpoint_starts_again_from_zero(tmp_path):
    """Killed while writing its first checkpoint: its rows up to the one that checkpoint fell
    due at (step 200) and its best policy of that evaluation are what a start from step 0
    writes again, so it starts again, without them."""
    full = metrics_rows(train_tiny(tmp_path, "full", steps=300))
    run = tmp_path / "run"
    trainer = Trainer(TrainConfig(**{**TINY_RUN, "steps": 300}), run, progress=False)
    trainer.save_checkpoint = _killed
    with pytest.raises(_Killed):
        trainer.train()
    assert latest_checkpoint(run) is None and [r["step"] for r in metrics_rows(run)] == [
        "100",
        "200",
    ]
    assert (run / "best_policy.msgpack").is_file() and not (run / "policy.msgpack").exists()
    with pytest.warns(UserWarning, match="starts again from step 0"):
        resumed = Trainer.resume(run, progress=False)
    assert resumed.step == 0 and metrics_rows(run) == []
    assert not (run / "best_policy.msgpack").exists() and not (run / "best_policy.json").exists()
    assert metrics_rows(resumed.train()) == full


@pytest.mark.integration
def test_a_run_with_results_and_no_checkpoint_is_refused_and_keeps_them(tmp_path, capsys):
    """A finished run whose checkpoints were removed (to free the disk) has nothing to resume
    from: a start from step 0 would delete its metrics and policies, so resume refuses it,
    saying what it holds and how to train it again, and changes no file."""
    run = train_tiny(tmp_path, "run", steps=600)
    shutil.rmtree(run / "checkpoints")
    kept = ("metrics.csv", "config.json", "policy.msgpack", "best_policy.msgpack")
    before = {name: (run / name).read_bytes() for name in kept}
    with pytest.raises(ValueError, match="no complete checkpoint") as refused:
        Trainer.resume(run, progress=False)
    message = str(refused.value)
    assert str(run) in message and "6 metrics rows to step 600" in message
    assert "policy.msgpack" in message and "best_policy.msgpack" in message
    assert f"ilfo train --config {run / 'config.json'}" in message
    for argv in (
        ["train", "--resume", str(run)],
        ["train", "--resume", str(run), "--steps", "900"],
    ):
        err = _cli_error(capsys, argv)
        assert str(run) in err and "nothing can be resumed" in err
    # Killed after checkpoints since removed, before its final policy: its rows past the first
    # checkpoint's are kept too.
    (run / "policy.msgpack").unlink()
    with pytest.raises(ValueError, match="6 metrics rows to step 600"):
        Trainer.resume(run, progress=False)
    assert {name: (run / name).read_bytes() for name in kept if name != "policy.msgpack"} == {
        name: data for name, data in before.items() if name != "policy.msgpack"
    }
    RunLock(run).acquire().release()  # the refusal let the run go
    # What the message says to do starts a new run from its config.
    argv = ["train", "--no-progress", "--config", str(run / "config.json")]
    assert main([*argv, "--out", str(tmp_path / "again"), "--steps", "200"]) == 0
    (again,) = (tmp_path / "again").iterdir()
    assert json.loads((again / "config.json").read_text())["eval_every"] == TINY_RUN["eval_every"]


def _write_rows(run, rows):
    lines = ["step,episode,wall_time", *(f"{s},{k + 1},{w}" for k, (s, w) in enumerate(rows))]
    (run / "metrics.csv").write_text("\n".join(lines) + "\n")


def test_results_past_the_first_checkpoint_are_read_off_the_rows_policies_and_clock(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    by_steps = TrainConfig(**{**TINY_RUN, "steps": 600})  # the first checkpoint falls due at 200
    assert results_past_first_checkpoint(run, by_steps) is None  # nothing logged yet
    _write_rows(run, [(100, 0.1), (200, 0.2)])  # killed while checkpointing at 200
    assert results_past_first_checkpoint(run, by_steps) is None
    (run / "metrics.csv").write_text(
        (run / "metrics.csv").read_text() + "300,3\n"  # a row the kill cut short
    )
    assert results_past_first_checkpoint(run, by_steps) is None
    _write_rows(run, [(100, 0.1), (200, 0.2), (300, 0.3)])
    assert results_past_first_checkpoint(run, by_steps) == "3 metrics rows to step 300"
    # By the clock (checkpoint_minutes: 1 s here), as the loop checkpoints by it.
    by_clock = TrainConfig(**{**TINY_RUN, "steps": 600, "checkpoint_every": 10**6,
                              "checkpoint_minutes": 1 / 60})  # fmt: skip
    assert results_past_first_checkpoint(run, by_clock) is None  # 0.3 s: none due yet
    _write_rows(run, [(100, 0.5), (200, 2.5)])
    assert results_past_first_checkpoint(run, by_clock) is None  # due after its last row
    _write_rows(run, [(100, 0.5), (200, 2.5), (300, 3.0)])
    assert results_past_first_checkpoint(run, by_clock) == "3 metrics rows to step 300"
    # A final policy (written after the last checkpoint), or a best policy past the first
    # checkpoint without the rows.
    (run / "metrics.csv").unlink()
    (run / "policy.msgpack").write_bytes(b"x")
    assert results_past_first_checkpoint(run, by_steps) == "policy.msgpack"
    (run / "policy.msgpack").unlink()
    (run / "best_policy.json").write_text(json.dumps({"step": 200}))
    assert results_past_first_checkpoint(run, by_steps) is None  # evaluated as it fell due
    (run / "best_policy.json").write_text(json.dumps({"step": 400}))
    assert results_past_first_checkpoint(run, by_steps) == "best_policy.json"


@pytest.mark.integration
def test_checkpoints_follow_the_clock_as_well_as_the_steps(tmp_path, monkeypatch):
    saved = []
    original = Trainer.save_checkpoint

    def record(self):
        saved.append(self.step)
        return original(self)

    monkeypatch.setattr(Trainer, "save_checkpoint", record)
    huge = 10**9
    train_tiny(tmp_path, "clock", steps=300, checkpoint_every=huge, checkpoint_minutes=1e-9)
    assert saved == [100, 200, 300]  # each episode took longer than the clock's interval
    saved.clear()
    train_tiny(tmp_path, "steps_only", steps=300, checkpoint_every=huge, checkpoint_minutes=0)
    assert saved == [300]  # the end of the run only
    assert TrainConfig().checkpoint_minutes == 10.0
    plan = Trainer(TrainConfig(**TINY_RUN), tmp_path / "p", progress=False).checkpoint_plan()
    assert "every 200 steps and every 10 min" in plan and str(tmp_path / "p") in plan
    for bad in (-1, float("nan"), "10", True):
        with pytest.raises(ValueError, match="checkpoint_minutes"):
            TrainConfig(**{**TINY_RUN, "checkpoint_minutes": bad})


@pytest.mark.integration
def test_resume_with_steps_writes_config_only_after_loading_and_refuses_to_shorten(tmp_path):
    run = train_tiny(tmp_path, "run", steps=300)
    config_bytes = (run / "config.json").read_bytes()
    with pytest.raises(ValueError, match="has done 300 steps already"):
        Trainer.resume(run, progress=False, steps=200)
    agent = latest_checkpoint(run) / "agent.msgpack"
    good = agent.read_bytes()
    agent.write_bytes(good[: len(good) // 2])  # truncated
    with pytest.raises(ValueError, match=r"agent\.msgpack is not a readable agent checkpoint"):
        Trainer.resume(run, progress=False, steps=400)
    assert (run / "config.json").read_bytes() == config_bytes  # neither call touched it
    agent.write_bytes(good)
    assert Trainer.resume(run, progress=False, steps=300).step == 300  # equal: nothing to do


# -------------------------------------------------------------------- kills at named moments
def _tensorboard_steps(run_dir, tag="proxy_return"):
    """Steps of ``tag`` in a run's TensorBoard events as TensorBoard shows them: a session start
    at step S (a writer opened with purge_step S) hides the events at S and after."""
    from tensorboardX.proto import event_pb2

    steps = []
    for path in sorted((run_dir / "tb").glob("events.out.tfevents.*")):
        data = path.read_bytes()
        pos = 0
        while pos + 12 <= len(data):
            (length,) = struct.unpack("<Q", data[pos : pos + 8])
            event = event_pb2.Event.FromString(data[pos + 12 : pos + 12 + length])
            pos += 12 + length + 4
            if event.HasField("session_log") and event.session_log.status == 1:
                steps = [s for s in steps if s < event.step]
            steps += [event.step for v in event.summary.value if v.tag == tag]
    return steps


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    return metrics_rows(train_tiny(tmp_path_factory.mktemp("reference"), "full"))


@pytest.mark.integration
@pytest.mark.parametrize(
    "fault",
    [
        "checkpoint_before_cleanup:1",  # the first checkpoint renamed, nothing after it
        "episode_end:3",  # rows logged after the last checkpoint
        pytest.param("checkpoint_before_rename:2", marks=pytest.mark.slow),
        pytest.param("checkpoint_before_cleanup:2", marks=pytest.mark.slow),
        pytest.param("episode_end:6", marks=pytest.mark.slow),  # the last row, unsaved
    ],
)
def test_a_run_killed_at_any_moment_resumes_to_the_uninterrupted_numbers(
    tmp_path, fault, uninterrupted
):
    env = {
        **os.environ,
        FAULT_ENV: fault,
        "ILFO_COMPILATION_CACHE": jax.config.jax_compilation_cache_dir,  # the session's
    }
    argv = [sys.executable, "-m", "ilfo.cli", *_cli_args(tmp_path / "runs")]
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == -9, done.stderr  # SIGKILL, as an OOM kill or a crash
    (run,) = list((tmp_path / "runs").iterdir())
    trainer = Trainer.resume(run, progress=False)
    assert metrics_rows(trainer.train()) == uninterrupted
    assert _tensorboard_steps(run) == [int(r["step"]) for r in uninterrupted]


# ------------------------------------------------------------------ clear errors, never tracebacks
def _cli_error(capsys, argv, code=2):
    assert main(argv) == code
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith("ilfo: error: ")
    return err


@pytest.mark.integration
def test_damaged_run_files_are_clear_errors_that_name_the_file(tmp_path, capsys):
    run = train_tiny(tmp_path, "run", steps=200)
    config, policy = run / "config.json", run / "policy.msgpack"
    good_config, good_policy = config.read_bytes(), policy.read_bytes()

    policy.write_bytes(good_policy[:100])
    assert "policy.msgpack is not a readable policy" in _cli_error(capsys, ["eval", str(run)])
    policy.write_bytes(os.urandom(2000))
    assert str(policy) in _cli_error(capsys, ["eval", str(run)])
    policy.write_bytes(good_policy)

    for damaged, message in [
        (good_config[: len(good_config) // 2], "is not valid JSON"),
        (b"\xff\xfe" + good_config, "is not UTF-8"),
        (
            json.dumps({**json.loads(good_config), "bogus": 1}).encode(),
            "unknown setting(s) 'bogus'",
        ),
        (json.dumps({**json.loads(good_config), "steps": "many"}).encode(), "steps must be an"),
        (b"[1, 2]", "must hold a JSON object"),
    ]:
        config.write_bytes(damaged)
        for argv in (["eval", str(run)], ["train", "--resume", str(run)]):
            err = _cli_error(capsys, argv)
            assert str(config) in err and message in err, err
    # The env's or the networks' sizes changed under a checkpoint: named, not a JAX shape error.
    changed = json.loads(good_config)
    changed["td3"]["critic_hidden"] = [32, 32]
    config.write_text(json.dumps(changed))
    err = _cli_error(capsys, ["train", "--resume", str(run), "--steps", "300"])
    assert "agent.msgpack" in err and "network sizes changed" in err
    config.write_bytes(good_config)

    replay = latest_checkpoint(run) / "replay.npz"
    replay.write_bytes(os.urandom(500))
    err = _cli_error(capsys, ["train", "--resume", str(run), "--steps", "300"])
    assert "replay.npz is not a replay buffer file" in err and "allow_pickle" not in err


def test_an_unwritable_out_is_one_line(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    err = _cli_error(capsys, _cli_args(blocker / "runs", steps=200), code=1)
    assert str(blocker) in err


@pytest.mark.integration
def test_a_checkpoint_is_on_the_disk_before_its_rename_and_before_older_ones_go(
    tmp_path, monkeypatch
):
    """A power loss must not leave the new checkpoint's name with empty files and no older
    checkpoint: its files and directory (and metrics.csv) are flushed, then renamed, then the
    rename flushed, and only then is the older checkpoint removed."""
    import shutil

    events = []
    fsync, replace, rmtree = os.fsync, os.replace, shutil.rmtree

    def record_fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        fsync(fd)

    def record_replace(src, dst):
        events.append(("replace", str(src), str(dst)))
        replace(src, dst)

    def record_rmtree(path, *args, **kwargs):
        events.append(("rmtree", str(path)))
        rmtree(path, *args, **kwargs)

    monkeypatch.setattr(os, "fsync", record_fsync)
    monkeypatch.setattr(os, "replace", record_replace)
    monkeypatch.setattr(shutil, "rmtree", record_rmtree)
    run = train_tiny(tmp_path, "run", steps=200, checkpoint_every=100)
    root = run / "checkpoints"
    final = root / "step_000000200"
    tmp = root / ".tmp_step_000000200"
    rename = events.index(("replace", str(tmp), str(final)))
    removal = events.index(("rmtree", str(root / "step_000000100")))
    synced_before = {e[1] for e in events[:rename] if e[0] == "fsync"}
    files = {str(tmp / p.relative_to(final)) for p in final.rglob("*")}
    assert files and files | {str(tmp)} <= synced_before
    assert ("fsync", str(root)) in events[rename:removal]
    # metrics.csv too: resume drops rows past the checkpoint, and would never log lost ones.
    assert str(run / "metrics.csv") in synced_before


@pytest.mark.integration
def test_a_full_disk_during_a_checkpoint_is_one_line_and_keeps_what_was_written(
    tmp_path, capsys, monkeypatch
):
    from ilfo.replay import ReplayBuffer

    full = metrics_rows(train_tiny(tmp_path, "full", steps=600))
    original, calls = ReplayBuffer.save, []

    def save(self, path):
        calls.append(path)
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        original(self, path)

    monkeypatch.setattr(ReplayBuffer, "save", save)
    err = _cli_error(capsys, _cli_args(tmp_path / "runs"), code=1)
    assert "No space left on device" in err and "replay.npz" in err
    monkeypatch.setattr(ReplayBuffer, "save", original)
    (run,) = list((tmp_path / "runs").iterdir())
    assert latest_checkpoint(run).name == "step_000000200"
    assert metrics_rows(Trainer.resume(run, progress=False).train()) == full


@pytest.mark.integration
def test_the_resume_hint_is_a_command_the_user_can_run(monkeypatch, tmp_path):
    import shutil

    from ilfo import cli

    venv_ilfo = str(tmp_path / ".venv" / "bin" / "ilfo")
    monkeypatch.setattr(sys, "argv", [venv_ilfo, "train"])
    monkeypatch.setattr(shutil, "which", lambda name: None)  # the venv is not activated
    assert cli._command() == venv_ilfo
    monkeypatch.setattr(shutil, "which", lambda name: venv_ilfo)  # it is
    assert cli._command() == "ilfo"
    monkeypatch.setattr(sys, "argv", ["-c"])
    assert cli._command() == f"{sys.executable} -m ilfo.cli"


# --------------------------------------------------------------------------- bad demo files
def _demo_corpus(tmp_path):
    """(name, path) of bad demonstration files, each a different way of being wrong."""
    good = demos.load(DEMOS)
    valid = tmp_path / "valid.npz"
    demos.save(valid, good.episodes[:2], "Hopper-v5")
    obs = np.concatenate([e.observations for e in good.episodes[:2]])
    lengths = np.array([len(e.observations) for e in good.episodes[:2]])
    steps = int(lengths.sum() - len(lengths))
    base = {
        "schema_version": np.array(1),
        "env_id": np.array("Hopper-v5"),
        "provenance": np.array("{}"),
        "episode_lengths": lengths,
        "observations": obs,
        "actions": np.zeros((steps, 3)),
        "rewards": np.ones(steps),
    }
    variants = {
        "nan_observations": {
            "observations": np.where(np.arange(len(obs))[:, None] == 5, np.nan, obs)
        },
        "inf_observations": {"observations": np.where(obs > 1.0, np.inf, obs)},
        "nan_rewards": {"rewards": np.where(np.arange(steps) == 7, np.nan, 1.0)},
        "inf_actions": {"actions": np.full((steps, 3), np.inf)},
        "string_observations": {"observations": obs.astype(str)},
        "bool_terminated_wrong_dtype": {"terminated": np.zeros(steps, dtype=np.int8)},
        "observations_3d": {"observations": obs[:, :, None]},
        "lengths_do_not_add_up": {"episode_lengths": lengths + 1},
        "zero_length_episode": {"episode_lengths": np.array([1, len(obs) - 1])},
        "no_episodes": {"episode_lengths": np.array([], dtype=np.int64)},
        "float_lengths": {"episode_lengths": lengths.astype(float)},
        "rewards_too_short": {"rewards": np.ones(steps - 1)},
        "actions_scalar": {"actions": np.array(1.0)},
        "pickled_objects": {"observations": np.array([object()] * len(obs), dtype=object)},
        "bad_schema": {"schema_version": np.array("one")},
        "bad_provenance": {"provenance": np.array("{not json")},
    }
    corpus = []
    for name, change in variants.items():
        path = tmp_path / f"{name}.npz"
        np.savez(path, **{**base, **change})
        corpus.append((name, path))
    data = valid.read_bytes()
    for fraction in (0.1, 0.5, 0.9, 0.999):
        path = tmp_path / f"truncated_{fraction}.npz"
        path.write_bytes(data[: int(len(data) * fraction)])
        corpus.append((f"truncated_{fraction}", path))
    rng = np.random.default_rng(0)
    for k in range(4):  # random bytes, and a zip header on random bytes
        path = tmp_path / f"garbage_{k}.npz"
        path.write_bytes((b"PK\x03\x04" if k % 2 else b"") + rng.bytes(3000))
        corpus.append((f"garbage_{k}", path))
    return valid, corpus


def test_every_bad_demo_file_is_a_clear_error_on_every_path(tmp_path, capsys):
    from ilfo.training import load_demos

    valid, corpus = _demo_corpus(tmp_path)
    assert len(demos.load(valid).episodes) == 2
    for name, path in corpus:
        for read in (demos.load, demos.load_any):
            with pytest.raises(ValueError) as caught:
                read(path)
            assert str(path) in str(caught.value), name
            assert "allow_pickle" not in str(caught.value), name
        with pytest.raises(ValueError, match=str(path)):  # ilfo train's path
            load_demos(TrainConfig(**{**TINY_RUN, "demos": str(path)}))
        err = _cli_error(capsys, ["demos", "info", str(path)])
        assert str(path) in err, name
    with pytest.raises(ValueError, match="holds demos of Hopper-v5, not Walker2d-v5"):
        load_demos(TrainConfig(**{**TINY_RUN, "demos": str(valid), "env": "Walker2d-v5"}))


def test_sinkhorn_refuses_costs_beyond_float64_instead_of_returning_nan():
    from ilfo.ot import cost_matrix, sinkhorn

    rng = np.random.default_rng(0)
    cost = cost_matrix(rng.normal(size=(30, 3)), rng.normal(size=(20, 3)))
    for scale in (1e20, 1e100, 1e300):
        with pytest.raises(ValueError, match="beyond what float64 resolves"):
            sinkhorn(cost * scale)
        with pytest.raises(ValueError, match="beyond what float64 resolves"):
            sinkhorn(cost * scale, init=sinkhorn(cost).potentials)
    with pytest.raises(ValueError, match="beyond what float64 resolves"):
        sinkhorn(cost + 1e20)  # a huge offset: the same plan in exact arithmetic, not in float64
    large = sinkhorn(cost * 1e3, max_iter=50)  # large but resolvable: a result, maybe unconverged
    assert np.isfinite(large.plan).all() and np.isfinite(large.cost)


@pytest.mark.integration
def test_a_snapshot_leaves_the_buffer_out_and_resumes_after_refilling_it(tmp_path, capsys):
    run = train_tiny(tmp_path, "run", steps=400)  # checkpoints at 200 and 400
    out = tmp_path / "carried"
    assert main(["snapshot", str(run), str(out)]) == 0
    assert "MiB" in capsys.readouterr().out
    (ckpt,) = (out / "checkpoints").iterdir()
    assert ckpt.name == "step_000000400"
    assert not (ckpt / "replay.npz").exists() and (ckpt / "replay.omitted").is_file()
    assert not (out / "tb").exists() and (out / "metrics.csv").is_file()
    assert (ckpt / "best_policy.msgpack").is_file()  # its own best, for a resume to put back
    assert (out / "demos.json").read_bytes() == (run / "demos.json").read_bytes()
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    run_size = sum(f.stat().st_size for f in run.rglob("*") if f.is_file())
    assert size < run_size - (run / "checkpoints" / ckpt.name / "replay.npz").stat().st_size
    assert main(["snapshot", str(run), str(out)]) != 0  # never over an existing directory
    assert "exists" in capsys.readouterr().err
    with pytest.warns(UserWarning, match="refilled by 200 steps"):
        trainer = Trainer.resume(out, progress=False, steps=800)
    assert trainer.step == 400 and trainer.buffer.size == 0
    rows = metrics_rows(trainer.train())
    by_step = {int(r["step"]): r for r in rows}
    # Steps 400-600 refill the buffer with the policy's own episodes (no updates), then
    # updates resume; every step is logged once.
    assert [int(r["step"]) for r in rows] == list(range(100, 900, 100))
    assert not by_step[500]["critic_loss"] and not by_step[600]["critic_loss"]
    assert by_step[700]["critic_loss"] and by_step[800]["critic_loss"]
    # A snapshot of the continued run carries the refill's end with it.
    again = Trainer.resume(out, progress=False)
    assert again.step == 800 and again.refill_until == 600
    again._lock.release()


@pytest.mark.integration
def test_a_snapshot_taken_mid_refill_keeps_refilling(tmp_path):
    run = train_tiny(tmp_path, "run", steps=400)
    out = tmp_path / "carried"
    with pytest.raises(ValueError, match="inside"):  # a copy into what it copies
        snapshot_run(run, run / "carried")
    snapshot_run(run, out)
    with pytest.raises(FileExistsError):
        snapshot_run(run, out)
    with pytest.warns(UserWarning, match="refilled"):
        trainer = Trainer.resume(out, progress=False, steps=500)
    trainer.train()  # stops at 500, inside the refill (it lasts to 600)
    resumed = Trainer.resume(out, progress=False, steps=700)
    assert resumed.step == 500 and resumed.refill_until == 600
    rows = {int(r["step"]): r for r in metrics_rows(resumed.train())}
    assert not rows[600]["critic_loss"] and rows[700]["critic_loss"]


@pytest.mark.integration
def test_an_on_policy_run_continues_exactly_from_a_snapshot(tmp_path):
    """Its buffer is the batch collected since its last update, part of its state: the
    snapshot keeps it (and a snapshot without it, from before, is refused clearly)."""
    sil = dict(algo="sil", trpo={"hidden": (16, 16), "batch_steps": 200, "value_iters": 5},
               sil={"critic_hidden": (16, 16), "critic_features": 8})  # fmt: skip
    full = train_tiny(tmp_path, "full", steps=500, **sil)
    run = train_tiny(tmp_path, "run", steps=300, **sil)  # its checkpoint at 300, mid-batch
    out = snapshot_run(run, tmp_path / "carried")
    (ckpt,) = (out / "checkpoints").iterdir()
    assert (ckpt / "replay.npz").is_file() and not (ckpt / "replay.omitted").exists()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no refill: nothing to warn of
        resumed = Trainer.resume(out, progress=False, steps=500)
    assert resumed.buffer.size > 0  # the batch pending at 300 (it updates at episode ends)
    assert metrics_rows(resumed.train()) == metrics_rows(full)
    older = snapshot_run(run, tmp_path / "older")  # as snapshots were before they kept it
    (ckpt,) = (older / "checkpoints").iterdir()
    (ckpt / "replay.npz").unlink()
    (ckpt / "replay.omitted").write_text("{}")
    with pytest.raises(ValueError, match="on-policy run keeps its pending batch"):
        Trainer.resume(older, progress=False)


def test_truncating_metrics_drops_rows_past_the_step_and_a_torn_row(tmp_path):
    """Resume drops the rows logged after its checkpoint, and the last row a kill cut short
    (here "3", the start of "3000,..."), through a renamed file (nothing left beside it)."""
    from ilfo.training.metrics import METRIC_FIELDS, MetricsLog, read_metrics, truncate_metrics

    log = MetricsLog(tmp_path)
    for step in (1000, 2000, 2500):
        log.write({"step": step, "episode": step // 1000, "proxy_return": -1.5})
    with (tmp_path / "metrics.csv").open("a") as f:
        f.write("3")
    truncate_metrics(tmp_path / "metrics.csv", 2000)
    rows = read_metrics(tmp_path)
    assert [r["step"] for r in rows] == ["1000", "2000"] and list(rows[0]) == METRIC_FIELDS
    assert rows[1]["proxy_return"] == "-1.5"
    assert sorted(p.name for p in tmp_path.iterdir() if "metrics" in p.name) == ["metrics.csv"]
