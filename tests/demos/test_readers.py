"""Readers for Minari, D4RL and imitation files: round trips, detection, and every bad file."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from ilfo import demos
from ilfo.demos import DemoFile, Episode

# ----------------------------------------------------------------------------------------------
# Writers of each format (test-only), laid out as the real libraries lay their files out.


def _episodes(seed=0, lengths=(5, 9, 3), obs_dim=4, act_dim=2):
    rng = np.random.default_rng(seed)
    return [
        Episode(
            rng.normal(size=(t + 1, obs_dim)),
            rng.normal(size=(t, act_dim)).astype(np.float32),
            rng.normal(size=t),
        )
        for t in lengths
    ]


def _write_minari(root, episodes, env_id="Hopper-v5", dataset_id="hopper/test-v0", old=False):
    """Minari's HDF5 layout: <root>/<dataset_id>/data/main_data.hdf5 (+ metadata.json).

    ``old``: metadata as attributes of the file's root (Minari < 0.4.2) instead of metadata.json.
    Episode observations may be an ndarray or a dict (nested group) of them.
    """
    data = Path(root) / dataset_id / "data"
    data.mkdir(parents=True)
    spec = json.dumps({"id": env_id, "entry_point": "x:y", "max_episode_steps": 1000})
    meta = {
        "dataset_id": dataset_id,
        "env_spec": spec,
        "total_episodes": len(episodes),
        "total_steps": sum(len(e["actions"]) for e in episodes),
        "data_format": "hdf5",
        "minari_version": "0.5.1",
    }
    with h5py.File(data / "main_data.hdf5", "w") as f:
        if old:
            f.attrs.update(meta)
        for i, ep in enumerate(episodes):
            g = f.create_group(f"episode_{i}")
            g.attrs["id"] = i
            g.attrs["total_steps"] = len(ep["actions"])
            _write_tree(g, "observations", ep["observations"])
            for key in ("actions", "rewards", "terminations", "truncations"):
                if key in ep:
                    g.create_dataset(key, data=ep[key])
    if not old:
        (data / "metadata.json").write_text(json.dumps(meta))
    return data.parent


def _write_tree(group, name, value):
    if isinstance(value, dict):
        sub = group.create_group(name)
        for key, v in value.items():
            _write_tree(sub, key, v)
    else:
        group.create_dataset(name, data=value)


def _minari_eps(episodes):
    return [
        {
            "observations": e.observations,
            "actions": e.actions,
            "rewards": e.rewards,
            "terminations": np.zeros(len(e.rewards), bool),
            "truncations": np.eye(1, len(e.rewards), len(e.rewards) - 1, dtype=bool)[0],
        }
        for e in episodes
    ]


def _write_d4rl(path, episodes, next_obs=True, flags=("terminals", "timeouts"), last_flag=True):
    """D4RL's flat layout: one row per transition, the episode's end flagged on its last row."""
    cols = {"observations": [], "next_observations": [], "actions": [], "rewards": []}
    terminals, timeouts = [], []
    for i, e in enumerate(episodes):
        t = len(e.actions)
        cols["observations"].append(e.observations[:-1])
        cols["next_observations"].append(e.observations[1:])
        cols["actions"].append(e.actions)
        cols["rewards"].append(e.rewards)
        end = np.zeros(t, bool)
        end[-1] = last_flag or i < len(episodes) - 1
        terminals.append(end if i % 2 == 0 else np.zeros(t, bool))
        timeouts.append(end if i % 2 == 1 else np.zeros(t, bool))
    with h5py.File(path, "w") as f:
        for key, parts in cols.items():
            if key != "next_observations" or next_obs:
                f.create_dataset(key, data=np.concatenate(parts))
        if "terminals" in flags:
            f.create_dataset("terminals", data=np.concatenate(terminals))
        if "timeouts" in flags:
            f.create_dataset("timeouts", data=np.concatenate(timeouts))
        f.create_dataset("infos/qpos", data=np.zeros((sum(len(e.actions) for e in episodes), 2)))
        f.create_dataset("metadata/algorithm", data="SAC")
    return path


def _write_imitation(path, episodes, infos=True, rews=True):
    """imitation <= 0.3 ``types.save``: trajectories end to end, split points in ``indices``."""
    arrays = {
        "obs": np.concatenate([e.observations for e in episodes]),
        "acts": np.concatenate([e.actions for e in episodes]),
        "terminal": np.array([True] * len(episodes)),
        "indices": np.cumsum([len(e.actions) for e in episodes[:-1]]),
    }
    if infos:
        arrays["infos"] = np.array([{} for e in episodes for _ in e.actions], dtype=object)
    if rews:
        arrays["rews"] = np.concatenate([e.rewards for e in episodes])
    np.savez_compressed(path, **arrays)
    return path


def _assert_same(got, want, obs_only=False, saved=False):
    """``saved``: ``got`` went through ``demos.save``, which stores these observations and
    actions as float32 (rewards as float64)."""
    assert len(got) == len(want)
    dtype = np.float32 if saved else None
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g.observations, np.asarray(w.observations, dtype))
        if not obs_only:
            np.testing.assert_array_equal(g.actions, np.asarray(w.actions, dtype))
            np.testing.assert_array_equal(g.rewards, w.rewards)


class _Boom:
    """Unpickling this object creates a marker file: proof that something was unpickled."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (exec, (f"open({self.marker!r}, 'w').close()",))


# ----------------------------------------------------------------------------------------------
# Round trips and detection


@pytest.mark.parametrize("old", [False, True])
def test_minari_round_trip_from_dir_data_dir_and_file(tmp_path, old):
    episodes = _episodes()
    root = _write_minari(tmp_path, _minari_eps(episodes), old=old)
    for path in (root, root / "data", root / "data" / "main_data.hdf5"):
        assert demos.detect_format(path) == "minari"
        got = demos.load_any(path, env_id="Hopper-v5")
        assert got.env_id == "Hopper-v5"
        assert got.provenance["dataset_id"] == "hopper/test-v0"
        assert got.provenance["source_format"] == "minari"
        _assert_same(got.episodes, episodes)


def test_minari_episodes_in_numeric_order(tmp_path):
    episodes = _episodes(lengths=tuple(range(1, 13)))
    root = _write_minari(tmp_path, _minari_eps(episodes))
    got = demos.read_minari(root)
    assert [len(e.observations) for e in got.episodes] == list(range(2, 14))


def test_minari_dict_and_tuple_observations_are_flattened(tmp_path):
    rng = np.random.default_rng(1)
    t = 6
    obs = {
        "observation": rng.normal(size=(t + 1, 3)),
        "achieved_goal": rng.normal(size=(t + 1, 2)),
        "desired_goal": {f"_index_{k}": np.full((t + 1, 1), k, float) for k in range(11)},
    }
    ep = {"observations": obs, "actions": rng.normal(size=(t, 2)), "rewards": np.ones(t)}
    root = _write_minari(tmp_path, [ep, ep])
    got = demos.load_any(root)
    want = np.concatenate(
        [
            obs["achieved_goal"],
            *(obs["desired_goal"][f"_index_{k}"] for k in range(11)),
            obs["observation"],
        ],
        axis=1,
    )
    np.testing.assert_array_equal(got.episodes[0].observations, want)
    keys = got.provenance["observation_keys"]
    assert keys[0] == "achieved_goal" and keys[-1] == "observation"
    assert keys[1:3] == ["desired_goal/_index_0", "desired_goal/_index_1"]
    assert got.provenance["observation_sizes"][0] == 2 and len(keys) == 13


@pytest.mark.parametrize("flags", [("terminals", "timeouts"), ("terminals",), ("timeouts",)])
def test_d4rl_round_trip_with_next_observations(tmp_path, flags):
    episodes = _episodes()
    if flags != ("terminals", "timeouts"):  # one flag column must mark every end
        path = tmp_path / "d.hdf5"
        with h5py.File(_write_d4rl(path, episodes), "a") as f:
            ends = np.zeros(len(f["observations"]), bool)
            ends[np.cumsum([len(e.actions) for e in episodes]) - 1] = True
            for key in ("terminals", "timeouts"):
                del f[key]
            f.create_dataset(flags[0], data=ends)
    else:
        path = _write_d4rl(tmp_path / "d.hdf5", episodes)
    assert demos.detect_format(path) == "d4rl"
    got = demos.load_any(path, env_id="Hopper-v5")
    assert got.env_id == "Hopper-v5"
    assert got.provenance["final_transition_dropped"] is False
    assert got.provenance["unfinished_last_episode"] is False
    _assert_same(got.episodes, episodes)


def test_d4rl_without_next_observations_drops_each_last_transition(tmp_path):
    episodes = _episodes(lengths=(5, 1, 4))
    got = demos.read_d4rl(_write_d4rl(tmp_path / "d.h5", episodes, next_obs=False))
    assert got.env_id == "" and got.provenance["final_transition_dropped"] is True
    # The one-step episode keeps a single observation: it cannot be an episode any more.
    assert got.provenance["dropped_one_step_episodes"] == 1
    kept = [episodes[0], episodes[2]]
    want = [Episode(e.observations[:-1], e.actions[:-1], e.rewards[:-1]) for e in kept]
    _assert_same(got.episodes, want)


def test_d4rl_keeps_an_unfinished_last_episode(tmp_path):
    episodes = _episodes()
    got = demos.read_d4rl(_write_d4rl(tmp_path / "d.hdf5", episodes, last_flag=False))
    assert got.provenance["unfinished_last_episode"] is True
    _assert_same(got.episodes, episodes)


@pytest.mark.parametrize("rews", [True, False])
def test_imitation_round_trip_skips_pickled_infos(tmp_path, rews):
    episodes = _episodes()
    path = _write_imitation(tmp_path / "traj.npz", episodes, rews=rews)
    assert demos.detect_format(path) == "imitation"
    got = demos.load_any(path, env_id="Pendulum-v1")
    assert got.env_id == "Pendulum-v1"
    assert got.provenance["skipped_keys"] == ["infos"]
    _assert_same(got.episodes, episodes, obs_only=True)
    for g, w in zip(got.episodes, episodes, strict=True):
        np.testing.assert_array_equal(g.actions, w.actions)
        if rews:
            np.testing.assert_array_equal(g.rewards, w.rewards)
        else:
            assert g.rewards is None


def test_imitation_single_trajectory(tmp_path):
    # np.cumsum([]) is an empty float array: the reader must take it as "no split".
    episodes = _episodes(lengths=(7,))
    got = demos.load_any(_write_imitation(tmp_path / "one.npz", episodes, infos=False))
    _assert_same(got.episodes, episodes)


def test_ilfo_files_read_as_with_load(tmp_path):
    episodes = _episodes()
    path = tmp_path / "ilfo.npz"
    demos.save(path, episodes, "Hopper-v5", {"policy": "x"})
    assert demos.detect_format(path) == "ilfo"
    got = demos.load_any(path)
    assert got.env_id == "Hopper-v5" and got.provenance == {"policy": "x"}
    _assert_same(got.episodes, episodes, saved=True)


def test_every_format_converts_to_ilfo_and_back(tmp_path):
    episodes = _episodes()
    sources = [
        _write_minari(tmp_path / "m", _minari_eps(episodes)),
        _write_d4rl(tmp_path / "d.hdf5", episodes),
        _write_imitation(tmp_path / "i.npz", episodes),
    ]
    for k, src in enumerate(sources):
        data = demos.load_any(src, env_id="Hopper-v5")
        out = tmp_path / f"out{k}.npz"
        demos.save(out, data.episodes, data.env_id, data.provenance)
        back = demos.load(out)
        assert back.env_id == "Hopper-v5" and back.provenance == data.provenance
        _assert_same(back.episodes, episodes, saved=True)


def test_summarize(tmp_path):
    episodes = _episodes()
    s = demos.summarize(DemoFile(episodes, "Hopper-v5", {"a": 1}))
    returns = [e.rewards.sum() for e in episodes]
    assert s["episodes"] == 3 and s["lengths"] == [5, 9, 3] and s["transitions"] == 17
    assert (s["obs_dim"], s["action_dim"]) == (4, 2)
    assert s["return_mean"] == pytest.approx(np.mean(returns))
    assert s["return_std"] == pytest.approx(np.std(returns))
    assert s["return_max"] == pytest.approx(max(returns))
    json.dumps(s)
    bare = demos.summarize(DemoFile([Episode(e.observations) for e in episodes], ""))
    assert bare["action_dim"] is None and bare["return_mean"] is None


# ----------------------------------------------------------------------------------------------
# Bad files


def test_env_id_mismatch(tmp_path):
    root = _write_minari(tmp_path, _minari_eps(_episodes()))
    with pytest.raises(ValueError, match="'Hopper-v5', not of the requested 'Walker2d-v5'"):
        demos.load_any(root, env_id="Walker2d-v5")
    path = tmp_path / "ilfo.npz"
    demos.save(path, _episodes(), "Hopper-v5")
    with pytest.raises(ValueError, match="Walker2d-v5"):
        demos.load_any(path, env_id="Walker2d-v5")


def test_missing_paths_and_unknown_formats(tmp_path):
    with pytest.raises(FileNotFoundError):
        demos.load_any(tmp_path / "nothing.npz")
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01 definitely not demos" * 10)
    with pytest.raises(ValueError, match="no known demonstration format"):
        demos.load_any(junk)
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    with pytest.raises(ValueError, match=r"neither 'schema_version' \(ilfo\) nor 'obs'"):
        demos.load_any(other)
    h5 = tmp_path / "other.h5"
    with h5py.File(h5, "w") as f:
        f.create_dataset("states", data=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="neither episode_<i> groups"):
        demos.load_any(h5)
    with pytest.raises(ValueError, match=r"holds no Minari main_data\.hdf5"):
        demos.load_any(tmp_path)


def test_missing_keys(tmp_path):
    ep = _episodes()[0]
    p = tmp_path / "noidx.npz"
    np.savez(p, obs=ep.observations, acts=ep.actions)
    with pytest.raises(ValueError, match="lacks the key 'indices'"):
        demos.load_any(p)
    p = tmp_path / "noflags.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("observations", data=ep.observations)
    with pytest.raises(ValueError, match="lacks both 'terminals' and 'timeouts'"):
        demos.load_any(p)
    with pytest.raises(ValueError, match="lacks the 'observations' array"):
        demos.read_d4rl(_h5(tmp_path / "e.h5", terminals=[1]))
    eps = _minari_eps(_episodes())
    del eps[1]["observations"]
    eps[1]["observations"] = {}
    root = _write_minari(tmp_path / "m", eps)
    with pytest.raises(ValueError, match="episode_1/observations is an empty group"):
        demos.load_any(root)
    with h5py.File(root / "data" / "main_data.hdf5", "a") as f:
        del f["episode_1/observations"]
    with pytest.raises(ValueError, match="episode_1 lacks 'observations'"):
        demos.load_any(root)


def _h5(path, **arrays):
    with h5py.File(path, "w") as f:
        for key, value in arrays.items():
            f.create_dataset(key, data=value)
    return path


def test_wrong_shapes(tmp_path):
    episodes = _episodes()
    # imitation: actions do not add up to what obs and indices say.
    p = _write_imitation(tmp_path / "i.npz", episodes, infos=False)
    arrays = dict(np.load(p))
    np.savez(p, **{**arrays, "acts": arrays["acts"][:-1]})
    with pytest.raises(ValueError, match="'acts' has shape"):
        demos.load_any(p)
    np.savez(p, **{**arrays, "indices": np.array([3, 100])})
    with pytest.raises(ValueError, match="do not split"):
        demos.load_any(p)
    np.savez(p, **{**arrays, "terminal": np.ones(5, bool)})
    with pytest.raises(ValueError, match="'terminal' has shape"):
        demos.load_any(p)
    # D4RL: columns of different lengths.
    obs = np.zeros((6, 3))
    p = _h5(tmp_path / "d.h5", observations=obs, actions=np.zeros((5, 2)), terminals=np.ones(6))
    with pytest.raises(ValueError, match="'actions' has shape"):
        demos.load_any(p)
    p = _h5(tmp_path / "d2.h5", observations=obs, next_observations=obs[:, :2], terminals=[1] * 6)
    with pytest.raises(ValueError, match="next_observations"):
        demos.load_any(p)
    # Minari: T + 1 observations but the wrong number of rewards.
    eps = _minari_eps(episodes)
    eps[2]["rewards"] = np.zeros(7)
    with pytest.raises(ValueError, match=r"episode 2: rewards have shape \(7,\), not \(3,\)"):
        demos.load_any(_write_minari(tmp_path / "m", eps))
    eps = _minari_eps(episodes)
    eps[0]["observations"] = eps[0]["observations"][:1]
    eps[0]["actions"] = eps[0]["actions"][:0]
    eps[0]["rewards"] = eps[0]["rewards"][:0]
    with pytest.raises(ValueError, match="episode 0: observations have shape"):
        demos.load_any(_write_minari(tmp_path / "m2", eps))


def test_mismatched_dims_between_episodes(tmp_path):
    eps = _minari_eps(_episodes(obs_dim=3)[:2] + _episodes(obs_dim=4)[2:])
    with pytest.raises(ValueError, match="episode 2: observations have dim 4, episode 0 has 3"):
        demos.load_any(_write_minari(tmp_path / "a", eps))
    eps = _minari_eps(_episodes(act_dim=2)[:1] + _episodes(act_dim=5)[1:])
    with pytest.raises(ValueError, match="episode 1: actions have dim 5"):
        demos.load_any(_write_minari(tmp_path / "b", eps))
    eps = _minari_eps(_episodes())
    eps[1]["observations"] = {"a": eps[1]["observations"]}
    with pytest.raises(ValueError, match="observation keys"):
        demos.load_any(_write_minari(tmp_path / "c", eps))


@pytest.mark.parametrize("fmt", ["ilfo", "minari", "d4rl", "imitation"])
@pytest.mark.parametrize("field", ["observations", "rewards"])
def test_nan_and_inf(tmp_path, fmt, field):
    episodes = _episodes()
    bad = episodes[1]
    arr = getattr(bad, field).copy()
    arr[2] = np.nan if field == "observations" else np.inf
    episodes[1] = Episode(**{**bad.__dict__, field: arr})
    if fmt == "ilfo":
        with pytest.raises(ValueError, match=f"{field} contain NaN or inf"):
            demos.save(tmp_path / "refused.npz", episodes, "Hopper-v5")  # not written
        # A file from elsewhere: the good episodes' arrays with the bad row put back.
        path = tmp_path / "x.npz"
        demos.save(path, _episodes(), "Hopper-v5", compact=False)
        with np.load(path) as archive:
            arrays = dict(archive)
        first_row = len(episodes[0].observations) - (field == "rewards")
        arrays[field][first_row + 2] = arr[2]
        np.savez(path, **arrays)
    elif fmt == "minari":
        path = _write_minari(tmp_path, _minari_eps(episodes))
    elif fmt == "d4rl":
        path = _write_d4rl(tmp_path / "x.h5", episodes)
    else:
        path = _write_imitation(tmp_path / "x.npz", episodes)
    with pytest.raises(ValueError, match=f"{field} contain NaN or inf"):
        demos.load_any(path)


def _write_any(fmt, tmp_path):
    episodes = _episodes(lengths=(200, 300))
    if fmt == "ilfo":
        path = tmp_path / "x.npz"
        demos.save(path, episodes, "Hopper-v5")
        return path
    if fmt == "minari":
        return _write_minari(tmp_path, _minari_eps(episodes)) / "data" / "main_data.hdf5"
    if fmt == "d4rl":
        return _write_d4rl(tmp_path / "x.h5", episodes)
    return _write_imitation(tmp_path / "x.npz", episodes)


@pytest.mark.parametrize("fmt", ["ilfo", "minari", "d4rl", "imitation"])
def test_truncated_files(tmp_path, fmt):
    path = _write_any(fmt, tmp_path)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match="not a readable"):
        demos.load_any(path)


@pytest.mark.parametrize("fmt", ["ilfo", "imitation"])
def test_corrupt_npz_bytes(tmp_path, fmt):
    path = _write_any(fmt, tmp_path)
    raw = bytearray(path.read_bytes())
    mid = len(raw) // 3
    raw[mid : mid + 64] = bytes(range(64))
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError):
        demos.load_any(path)


def test_pickled_object_arrays_are_never_loaded(tmp_path):
    marker = tmp_path / "unpickled"
    episodes = _episodes()
    path = _write_imitation(tmp_path / "i.npz", episodes, infos=False)
    arrays = dict(np.load(path))
    boom = np.array([_Boom(marker)] * len(arrays["acts"]), dtype=object)
    np.savez(path, **arrays, infos=boom)
    got = demos.load_any(path)  # infos skipped, everything else read
    assert got.provenance["skipped_keys"] == ["infos"] and not marker.exists()
    np.savez(path, **{**arrays, "obs": np.array([_Boom(marker)], dtype=object)})
    with pytest.raises(ValueError, match="'obs' is an object array that would need unpickling"):
        demos.load_any(path)
    assert not marker.exists()
    ilfo = tmp_path / "ilfo.npz"
    demos.save(ilfo, episodes, "Hopper-v5")
    arrays = dict(np.load(ilfo))
    np.savez(ilfo, **{**arrays, "observations": np.array([_Boom(marker)], dtype=object)})
    with pytest.raises(ValueError):
        demos.load_any(ilfo)
    assert not marker.exists()
    np.load(ilfo, allow_pickle=True)["observations"]  # the marker does work when unpickled
    assert marker.exists()


def test_minari_refusals(tmp_path):
    arrow = tmp_path / "arrow-v0" / "data"
    arrow.mkdir(parents=True)
    (arrow / "metadata.json").write_text(json.dumps({"data_format": "arrow"}))
    with pytest.raises(ValueError, match="stored as 'arrow'"):
        demos.load_any(arrow.parent)
    eps = _minari_eps(_episodes())
    eps[0]["observations"] = {"text": np.array([b"a"] * 6)}
    with pytest.raises(ValueError, match="not numbers"):
        demos.load_any(_write_minari(tmp_path / "t", eps))


def test_d4rl_without_timeouts_warns_of_joined_time_limit_ends(tmp_path):
    """Older files flag terminals only: an episode that ended at the time limit runs into the
    next. With next observations the joins are counted; without, the warning is general."""
    episodes = _episodes()
    path = _write_d4rl(tmp_path / "d.hdf5", episodes, flags=("terminals",))  # odd ones unflagged
    with pytest.warns(UserWarning, match=r"no 'timeouts', and at 1 unflagged rows"):
        got = demos.read_d4rl(path)
    assert len(got.episodes) == len(episodes) - 1  # the second ran into the third
    bare = _write_d4rl(tmp_path / "bare.hdf5", episodes, next_obs=False, flags=("terminals",))
    with pytest.warns(UserWarning, match="cut at terminals only"):
        demos.read_d4rl(bare)
