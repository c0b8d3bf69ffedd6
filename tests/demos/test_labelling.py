"""Offline labelling (`ilfo label`): rewards equal the library's, each format round-trips with
only its rewards changed, bad input is refused clearly."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from test_readers import _episodes, _minari_eps, _write_d4rl, _write_minari

from ilfo import demos
from ilfo.cli import main
from ilfo.demos import Episode
from ilfo.labelling import EpisodeLabeller, LabelConfig, label_dataset, label_episodes
from ilfo.rewards import OOPS, OOPSConfig


def _demos(tmp_path, seed=5):
    episodes = _episodes(seed=seed, lengths=(8, 7))
    path = tmp_path / "demos.npz"
    demos.save(path, [Episode(e.observations) for e in episodes], "Hopper-v5")
    return path, [e.observations for e in episodes]


def test_rewards_are_oops_couplings_squashed_and_top_k():
    rng = np.random.default_rng(0)
    expert = [rng.normal(size=(11, 3)), rng.normal(size=(9, 3)) + 2.0]
    episode = rng.normal(size=(10, 3))
    couplings = OOPS(expert).couplings(episode)
    costs = np.stack([c.row_costs for c in couplings])
    exp = EpisodeLabeller(expert, LabelConfig(squashing="exponential", alpha=5, beta=5))(episode)
    per_demo = 5 * np.exp(-5 * costs)
    np.testing.assert_allclose(exp, per_demo[np.argmax(per_demo.sum(1))])
    both = EpisodeLabeller(expert, LabelConfig(squashing="linear", alpha=10, top_k=2))(episode)
    np.testing.assert_allclose(both, (-10 * costs).mean(0))
    # The oops squashing against the nearest demo is OOPS's own reward with that demo selection.
    ours = EpisodeLabeller(expert, LabelConfig(squashing="oops"))(episode)
    reference = OOPS(expert, OOPSConfig(demo_selection="nearest"))(episode).rewards
    np.testing.assert_allclose(ours, reference)
    with pytest.raises(ValueError, match="top_k 3 exceeds"):
        EpisodeLabeller(expert, LabelConfig(top_k=3))
    with pytest.raises(ValueError, match="squashing"):
        LabelConfig(squashing="tanh")


def test_parallel_labels_equal_serial():
    rng = np.random.default_rng(1)
    expert = [rng.normal(size=(12, 4))]
    episodes = [rng.normal(size=(int(n), 4)) for n in rng.integers(5, 15, size=9)]
    serial = label_episodes(episodes, expert, workers=1)
    seen = []
    parallel = label_episodes(episodes, expert, workers=2, on_progress=seen.append)
    assert sum(seen) == len(episodes)
    for a, b in zip(serial, parallel, strict=True):
        np.testing.assert_allclose(a, b)


def test_ilfo_round_trip(tmp_path):
    demo_path, expert = _demos(tmp_path)
    data = tmp_path / "data.npz"
    episodes = _episodes(seed=1)
    demos.save(data, episodes, "Hopper-v5")
    summary = label_dataset(data, demo_path, tmp_path / "out.npz")
    assert (summary.format, summary.episodes) == ("ilfo", 3)
    out = demos.load(tmp_path / "out.npz")
    labeller = EpisodeLabeller(expert)
    for got, want in zip(out.episodes, episodes, strict=True):
        # Saved as float32 (rewards as float64, from the observations as given).
        np.testing.assert_array_equal(got.observations, want.observations.astype(np.float32))
        np.testing.assert_array_equal(got.actions, want.actions.astype(np.float32))
        np.testing.assert_allclose(got.rewards, labeller(want.observations))
    with pytest.raises(FileExistsError):
        label_dataset(data, demo_path, tmp_path / "out.npz")
    for bad in (0, -1, len(expert) + 1):  # -1 would have dropped the last demo silently
        with pytest.raises(ValueError, match="num_demos must be between 1 and"):
            label_dataset(data, demo_path, tmp_path / f"bad{bad}.npz", num_demos=bad)


def test_a_labelling_that_fails_midway_leaves_nothing_under_its_name(tmp_path, monkeypatch):
    import ilfo.labelling

    demo_path, _ = _demos(tmp_path)
    data = tmp_path / "data.npz"
    demos.save(data, _episodes(seed=1), "Hopper-v5")

    def half_written(dataset, out, data, rewards):
        out.write_bytes(b"half")
        raise OSError("No space left on device")

    monkeypatch.setattr(ilfo.labelling, "_write_ilfo", half_written)
    with pytest.raises(OSError, match="No space"):
        label_dataset(data, demo_path, tmp_path / "out.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.npz", "demos.npz"]


@pytest.mark.parametrize("next_obs", [True, False])
def test_d4rl_round_trip(tmp_path, next_obs):
    demo_path, expert = _demos(tmp_path)
    episodes = _episodes(seed=2, lengths=(6, 4, 5))
    path = _write_d4rl(tmp_path / "data.hdf5", episodes, next_obs=next_obs)
    label_dataset(path, demo_path, tmp_path / "out.hdf5", env_id="Hopper-v5")
    labeller = EpisodeLabeller(expert)
    with h5py.File(path) as before, h5py.File(tmp_path / "out.hdf5") as after:
        assert set(before) == set(after)
        for key in ("observations", "actions", "terminals", "timeouts"):
            np.testing.assert_array_equal(before[key][()], after[key][()])
        rewards = after["rewards"][()]
    start = 0
    for e in episodes:
        t = len(e.actions)
        obs = e.observations if next_obs else e.observations[:-1]
        want = labeller(obs)
        if not next_obs:  # the last row has no next state: the episode's last labelled reward
            want = np.append(want, want[-1])
        np.testing.assert_allclose(rewards[start : start + t], want, rtol=1e-6)
        start += t


def test_minari_round_trip(tmp_path):
    demo_path, expert = _demos(tmp_path)
    episodes = _episodes(seed=3)
    root = _write_minari(tmp_path / "datasets", _minari_eps(episodes))
    label_dataset(root, demo_path, tmp_path / "labelled")
    out = demos.load_any(tmp_path / "labelled")
    assert (tmp_path / "labelled" / "data" / "metadata.json").is_file()
    labeller = EpisodeLabeller(expert)
    for got, want in zip(out.episodes, episodes, strict=True):
        np.testing.assert_array_equal(got.actions, want.actions)
        np.testing.assert_allclose(got.rewards, labeller(want.observations))
    original = demos.load_any(root)  # the source is untouched
    np.testing.assert_array_equal(original.episodes[0].rewards, episodes[0].rewards)


def test_cli_and_bad_input(tmp_path, capsys):
    demo_path, _ = _demos(tmp_path)
    data = tmp_path / "data.npz"
    demos.save(data, _episodes(seed=4), "Hopper-v5")
    args = ["label", str(data), "--demos", str(demo_path), "--out", str(tmp_path / "o.npz")]
    assert main([*args, "--squashing", "linear", "--workers", "1", "--oops-reg", "0.1"]) == 0
    captured = capsys.readouterr()
    assert "3 episodes" in captured.out and "labelling" in captured.err  # the progress bar
    wide = tmp_path / "wide.npz"
    demos.save(wide, [Episode(np.zeros((5, 7)))], "Hopper-v5")
    assert main(["label", str(data), "--demos", str(wide), "--out", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "7-dim observations" in err and "labelling" not in err  # no bar before the error
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    assert main(["label", str(junk), "--demos", str(demo_path), "--out", str(tmp_path / "y")]) == 2
    assert main([*args[:4], "--out", str(tmp_path / "z.npz"), "--top-k", "5"]) == 2
    assert "top_k 5 exceeds" in capsys.readouterr().err
