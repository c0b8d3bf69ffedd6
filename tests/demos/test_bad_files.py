"""Damaged or foreign files are one-line errors naming the file, never tracebacks: .npz members
encrypted, compressed otherwise or declaring terabytes; settings JSON nested too deep; metrics
not UTF-8; demos whose width their env does not observe; a full disk naming the file."""

from __future__ import annotations

import errno
import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from ilfo import demos
from ilfo.cli import main
from ilfo.files import load_npz, read_settings_file, write_json_atomic

HOPPER = "Hopper-v5"


def _demo_file(path: Path, env_id: str = HOPPER, width: int = 11) -> Path:
    rng = np.random.default_rng(0)
    episodes = [
        demos.Episode(rng.normal(size=(6, width)), rng.normal(size=(5, 3)), np.ones(5))
        for _ in range(3)
    ]
    demos.save(path, episodes, env_id)
    return path


def _stored_copy(src: Path, out: Path, edit=None) -> Path:
    """``src``'s members written again uncompressed (so that raw headers can be patched),
    ``edit(name, data)`` changing a member's bytes."""
    with zipfile.ZipFile(src) as z:
        members = [(info.filename, z.read(info)) for info in z.infolist()]
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as z:
        for name, data in members:
            z.writestr(name, edit(name, data) if edit else data)
    return out


def _patch_headers(path: Path, member: str, *, flag: int = 0, method: int | None = None) -> None:
    """Set general-purpose ``flag`` bits or the compression ``method`` of ``member`` in its
    local and central-directory headers (zipfile writes neither)."""
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        local = z.getinfo(member).header_offset
    central = raw.index(b"PK\x01\x02")
    while raw[central + 46 : central + 46 + len(member)] != member.encode():
        central = raw.index(b"PK\x01\x02", central + 4)
    for at in (local + 6, central + 8):  # the flag word; the method word follows it
        flags = int.from_bytes(raw[at : at + 2], "little") | flag
        raw[at : at + 2] = flags.to_bytes(2, "little")
        if method is not None:
            raw[at + 2 : at + 4] = method.to_bytes(2, "little")
    path.write_bytes(bytes(raw))


def _huge_shape(name: str, data: bytes) -> bytes:
    """The observations' .npy header declaring 80 TiB of float rows, its length kept."""
    if name != "observations.npy":
        return data
    length = int.from_bytes(data[8:10], "little")
    header = data[10 : 10 + length].decode("latin1")
    itemsize = 4 if "<f4" in header else 8
    rows = 80 * 2**40 // (11 * itemsize)
    start = header.index("'shape': (") + len("'shape': (")
    end = header.index(")", start)
    new = header[:start] + f"{rows}, 11" + header[end:]
    new = new.rstrip() + " " * (length - len(new.rstrip()) - 1) + "\n"
    assert len(new) == length
    return data[:10] + new.encode("latin1") + data[10 + length :]


@pytest.fixture
def bad_demos(tmp_path):
    """Three damaged copies of a good demos file: (kind, path, the member named)."""
    good = _demo_file(tmp_path / "good.npz")
    encrypted = _stored_copy(good, tmp_path / "encrypted.npz")
    _patch_headers(encrypted, "observations.npy", flag=0x1)
    method = _stored_copy(good, tmp_path / "method.npz")
    _patch_headers(method, "episode_lengths.npy", method=99)
    huge = _stored_copy(good, tmp_path / "huge.npz", edit=_huge_shape)
    return [
        ("encrypted", encrypted, "observations.npy"),
        ("compression method 99", method, "episode_lengths.npy"),
        ("80.0 TiB", huge, "observations.npy"),
    ]


def _one_line_error(capsys, code: int, *names: object) -> str:
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith("ilfo: error: ") and "Traceback" not in err
    for name in names:
        assert str(name) in err, err
    return err


def test_damaged_npz_members_are_refused_before_reading(bad_demos):
    for kind, path, member in bad_demos:
        for read in (demos.load, demos.load_any, lambda p: load_npz(p, "replay buffer")):
            with pytest.raises(ValueError, match=kind) as info:
                read(path)
            assert str(path) in str(info.value) and repr(member) in str(info.value)
            assert "\n" not in str(info.value)


def test_damaged_npz_members_are_one_line_errors_in_every_command(bad_demos, capsys, tmp_path):
    dataset = _demo_file(tmp_path / "dataset.npz")
    for kind, path, member in bad_demos:
        commands = [
            ["demos", "info", str(path)],
            ["demos", "convert", str(path), str(tmp_path / "out.npz")],
            ["reward", "--demos", str(path)],
            ["label", str(dataset), "--demos", str(path), "--out", str(tmp_path / "l.npz")],
        ]
        for argv in commands:
            err = _one_line_error(capsys, main(argv), path, member)
            assert kind in err


def test_train_refuses_damaged_demos_in_one_line(bad_demos, capsys, tmp_path):
    _, path, member = bad_demos[2]
    argv = ["train", "--env", HOPPER, "--demos", str(path), "--out", str(tmp_path / "run")]
    _one_line_error(capsys, main([*argv, "--steps", "100", "--preset", "fast"]), path, member)


def test_an_imitation_npz_is_checked_too(tmp_path):
    src = tmp_path / "src.npz"
    np.savez(src, obs=np.zeros((4, 3)), acts=np.zeros((3, 2)), indices=np.array([], np.int64))
    path = _stored_copy(src, tmp_path / "imitation.npz")
    _patch_headers(path, "obs.npy", flag=0x1)
    with pytest.raises(ValueError, match=r"member 'obs.npy' is encrypted"):
        demos.load_any(path)


def test_a_valid_file_still_reads(tmp_path):
    good = _demo_file(tmp_path / "good.npz")
    stored = _stored_copy(good, tmp_path / "stored.npz")  # stored, not deflated: also fine
    for path in (good, stored):
        assert len(demos.load(path).episodes) == 3
        assert len(demos.load_any(path).episodes) == 3


# ------------------------------------------------------------------------- settings JSON
DEEP = "[" * 100_000 + "]" * 100_000


def test_deeply_nested_json_is_a_one_line_error(tmp_path, capsys):
    path = tmp_path / "deep.json"
    path.write_text('{"steps": ' + DEEP + "}")
    with pytest.raises(ValueError, match="nested too deeply") as info:
        read_settings_file(path)
    assert str(path) in str(info.value)
    _one_line_error(capsys, main(["train", "--config", str(path)]), path)


def test_a_run_config_nested_too_deeply_is_a_one_line_error(tmp_path, capsys):
    from ilfo.training import read_run_config

    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text('{"env": ' + DEEP + "}")
    with pytest.raises(ValueError, match="nested too deeply"):
        read_run_config(run)
    _one_line_error(capsys, main(["train", "--resume", str(run)]), run / "config.json")


def test_a_non_utf8_metrics_file_on_resume_names_it(tmp_path):
    from ilfo.training.metrics import read_metrics, truncate_metrics

    path = tmp_path / "metrics.csv"
    path.write_bytes(b"step,episode\n10,1\n\xff\xfe20,2\n")
    with pytest.raises(ValueError, match=r"metrics\.csv is not UTF-8 text") as info:
        truncate_metrics(path, 10)
    assert str(path) in str(info.value)
    with pytest.raises(ValueError, match="not UTF-8"):
        read_metrics(tmp_path)
    assert path.read_bytes().startswith(b"step,episode\n10,1\n\xff")  # left as it was


# ------------------------------------------------------------------ observation widths
def test_demos_narrower_than_their_env_observes_are_refused(tmp_path, capsys):
    path = _demo_file(tmp_path / "narrow.npz", HOPPER, width=5)
    for argv in (["demos", "info", str(path)], ["reward", "--demos", str(path)]):
        err = _one_line_error(capsys, main(argv), path)
        assert "5" in err and "11" in err and HOPPER in err


def test_widths_pass_for_the_right_width_and_unknown_envs(tmp_path, capsys):
    from ilfo.demos.env_check import check_observation_width, observation_widths

    assert main(["demos", "info", str(_demo_file(tmp_path / "ok.npz"))]) == 0
    capsys.readouterr()
    assert observation_widths("NoSuchEnv-v0") is None  # nothing to check against
    assert observation_widths("Ant-v5") == (105, 27)  # with or without the contact forces
    check_observation_width(demos.load(_demo_file(tmp_path / "x.npz", "", width=5)), "x")


# ------------------------------------------------------------------------ a full disk
def _disk_full(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_full_disk_names_the_json_file(tmp_path, monkeypatch):
    monkeypatch.setattr(Path, "write_text", _disk_full)
    with pytest.raises(OSError) as info:
        write_json_atomic(tmp_path / "config.json", {"a": 1})
    assert info.value.errno == errno.ENOSPC
    assert info.value.filename == str(tmp_path / "config.json")


def test_a_full_disk_names_the_metrics_file(tmp_path, monkeypatch):
    import csv

    from ilfo.training.metrics import MetricsLog

    log = MetricsLog(tmp_path)
    monkeypatch.setattr(csv.DictWriter, "writerow", _disk_full)
    with pytest.raises(OSError) as info:
        log.write({"step": 1, "episode": 1})
    log.close()
    assert info.value.errno == errno.ENOSPC
    assert info.value.filename == str(tmp_path / "metrics.csv")


def test_a_full_disk_names_the_checkpoint_file(tmp_path, monkeypatch):
    from ilfo.replay import ReplayBuffer
    from ilfo.training.checkpoint import Checkpoint, LoopState, save_checkpoint

    buffer = ReplayBuffer(10, 3, 2)
    ckpt = Checkpoint(LoopState(step=5, episode=1, elapsed=1.0), {"w": np.zeros(2)}, buffer)
    monkeypatch.setattr(ReplayBuffer, "save", _disk_full)
    with pytest.raises(OSError) as info:
        save_checkpoint(tmp_path, ckpt)
    assert info.value.errno == errno.ENOSPC
    assert info.value.filename.endswith("replay.npz")
    assert not list((tmp_path / "checkpoints").iterdir())  # nothing half-written left


def test_the_cli_prints_the_file_a_full_disk_stopped(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(Path, "write_text", _disk_full)
    out = tmp_path / "sweep"
    code = main(["sweep", "create", str(out), "--env", HOPPER, "--steps", "1000"])
    err = capsys.readouterr().err
    assert code == 1 and "sweep.json" in err and "No space left on device" in err, err


def test_json_of_settings_reads_back(tmp_path):
    path = tmp_path / "s.json"
    write_json_atomic(path, {"steps": 5})
    assert read_settings_file(path) == {"steps": 5}
    assert json.loads(path.read_text()) == {"steps": 5}
