import numpy as np
import pytest

from ilfo import demos
from ilfo.demos import Episode


def _episodes(rng, with_extras=True):
    out = []
    for length in (5, 9):
        obs = rng.normal(size=(length + 1, 3))
        if with_extras:
            out.append(Episode(obs, rng.normal(size=(length, 2)), rng.normal(size=length)))
        else:
            out.append(Episode(obs))
    return out


@pytest.mark.parametrize("with_extras", [True, False])
def test_round_trip(tmp_path, with_extras):
    episodes = _episodes(np.random.default_rng(0), with_extras)
    path = tmp_path / "d.npz"
    demos.save(path, episodes, "Hopper-v5", provenance={"policy": "test"})
    loaded = demos.load(path)
    assert loaded.env_id == "Hopper-v5" and loaded.provenance == {"policy": "test"}
    assert len(loaded.episodes) == 2
    for got, want in zip(loaded.episodes, episodes, strict=True):
        np.testing.assert_array_equal(got.observations, want.observations.astype(np.float32))
        if with_extras:
            np.testing.assert_array_equal(got.actions, want.actions.astype(np.float32))
            assert got.rewards.dtype == np.float64
            assert got.task_return == pytest.approx(want.rewards.sum())
        else:
            assert got.actions is None and got.task_return is None


def test_compact_storage_only_where_float32_loses_nothing(tmp_path):
    rng = np.random.default_rng(2)
    obs = rng.normal(size=(50, 3)) * [1.0, 100.0, 1e-3]
    path = tmp_path / "c.npz"
    demos.save(path, [Episode(obs)], "Hopper-v5")
    got = demos.load(path).episodes[0].observations
    assert got.dtype == np.float32
    error = np.abs(got - obs).max(axis=0)
    assert (error <= demos.npz.FLOAT32_TOLERANCE * obs.std(axis=0)).all()
    # compact=False keeps float64 exactly.
    demos.save(path, [Episode(obs)], "Hopper-v5", compact=False)
    np.testing.assert_array_equal(demos.load(path).episodes[0].observations, obs)
    # A column that varies by less than float32 resolves around its mean stays float64.
    tight = obs.copy()
    tight[:, 0] = 1000.0 + 1e-6 * rng.normal(size=50)
    assert not demos.npz.float32_is_lossless(tight)
    demos.save(path, [Episode(tight)], "Hopper-v5")
    np.testing.assert_array_equal(demos.load(path).episodes[0].observations, tight)
    # Constant columns round the same in every row: float32 where the constant survives.
    const = np.column_stack([np.full(50, 0.1), obs[:, 1]])
    assert demos.npz.float32_is_lossless(const)
    assert not demos.npz.float32_is_lossless(np.column_stack([np.full(50, 1e39), obs[:, 1]]))
    assert not demos.npz.float32_is_lossless(np.arange(6).reshape(3, 2))  # integers


def test_terminations_round_trip_and_score(tmp_path):
    obs, rewards = np.zeros((5, 3)), np.array([1.0, 2.0, 3.0, 4.0])
    terminated = np.array([False, False, True, True])
    path = tmp_path / "t.npz"
    demos.save(path, [Episode(obs, None, rewards, terminated)], "BipedalWalker-v3")
    (got,) = demos.load(path).episodes
    np.testing.assert_array_equal(got.terminated, terminated)
    assert got.task_return == 10.0 and got.task_score == 3.0  # terminated steps count 0
    assert Episode(obs, None, rewards).task_score == 10.0  # none recorded: the plain return
    bad = tmp_path / "bad.npz"
    arrays = dict(np.load(path, allow_pickle=False))
    np.savez(bad, **{**arrays, "terminated": np.array([0.0, 0.0, 1.0, 1.0])})
    with pytest.raises(ValueError, match="terminated must be boolean"):
        demos.load(bad)


def test_bad_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        demos.load(tmp_path / "missing.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip at all")
    with pytest.raises(ValueError, match=r"is not an \.npz archive"):
        demos.load(junk)
    partial = tmp_path / "partial.npz"
    np.savez(partial, observations=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="lacks the key"):
        demos.load(partial)
    pickled = tmp_path / "pickled.npz"
    np.savez(
        pickled,
        schema_version=1,
        episode_lengths=np.array([2]),
        observations=np.array([object(), object()], dtype=object),
    )
    with pytest.raises(ValueError, match="pickled Python objects"):
        demos.load(pickled)
    mismatched = tmp_path / "mismatched.npz"
    np.savez(
        mismatched, schema_version=1, episode_lengths=np.array([4]), observations=np.zeros((3, 2))
    )
    with pytest.raises(ValueError, match="do not match"):
        demos.load(mismatched)
    nan = tmp_path / "nan.npz"
    np.savez(
        nan, schema_version=1, episode_lengths=np.array([2]), observations=np.full((2, 2), np.nan)
    )
    with pytest.raises(ValueError, match="NaN"):
        demos.load(nan)


def test_save_refuses_what_load_would_refuse_and_keeps_the_old_file(tmp_path):
    rng = np.random.default_rng(5)
    path = tmp_path / "good.npz"
    demos.save(path, _episodes(rng), "Hopper-v5")
    before = path.read_bytes()
    bad = {
        "observations contain NaN": [Episode(np.full((4, 3), np.nan))],
        "not \\(T \\+ 1, d\\)": [Episode(np.zeros((1, 3)))],  # one observation
        "actions have shape": [Episode(np.zeros((4, 3)), actions=np.zeros((5, 2)))],
        "terminated must be boolean": [Episode(np.zeros((4, 3)), terminated=np.zeros(3, int))],
        "episode 0 has 3": [Episode(np.zeros((4, 3))), Episode(np.zeros((4, 2)))],
        "episodes 0 have actions, episodes 1 none": [
            Episode(np.zeros((4, 3)), actions=np.zeros((3, 2))),
            Episode(np.zeros((4, 3))),
        ],
    }
    for message, episodes in bad.items():
        with pytest.raises(ValueError, match=message):
            demos.save(path, episodes, "Hopper-v5")
    with pytest.raises(ValueError, match="env_id must be a string"):
        demos.save(path, _episodes(rng), None)
    with pytest.raises(FileNotFoundError, match=r"its folder .*nodir does not exist"):
        demos.save(tmp_path / "nodir" / "x.npz", _episodes(rng), "Hopper-v5")
    assert path.read_bytes() == before  # every refusal left the good file as it was
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.npz"]  # and no temporary


def test_a_save_that_fails_while_writing_keeps_the_old_file(tmp_path, monkeypatch):
    rng = np.random.default_rng(6)
    path = tmp_path / "good.npz"
    demos.save(path, _episodes(rng), "Hopper-v5")
    before = path.read_bytes()

    def disk_full(file, **arrays):
        file.write(b"PK half an archive")
        raise OSError("No space left on device")

    monkeypatch.setattr(np, "savez_compressed", disk_full)
    with pytest.raises(OSError, match="No space"):
        demos.save(path, _episodes(rng), "Hopper-v5")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.npz"]


def test_save_writes_exactly_the_path_given(tmp_path):
    episodes = _episodes(np.random.default_rng(6))
    for name in ("demos", "demos.json"):  # numpy would have written demos.npz, demos.json.npz
        with pytest.raises(ValueError, match=r"ends in \.npz"):
            demos.save(tmp_path / name, episodes, "Hopper-v5")
    assert not list(tmp_path.iterdir())
    demos.save(tmp_path / "d.npz", episodes, "Hopper-v5")
    assert demos.load(tmp_path / "d.npz").env_id == "Hopper-v5"
    link = tmp_path / "link.npz"  # a symlink is written through, not replaced
    link.symlink_to(tmp_path / "d.npz")
    demos.save(link, episodes[:1], "Walker2d-v5")
    assert link.is_symlink() and demos.load(tmp_path / "d.npz").env_id == "Walker2d-v5"
