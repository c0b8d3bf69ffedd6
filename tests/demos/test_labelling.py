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
    costs = np.stack([c.row_costs for c in couplings])  # rows of mass 1/9 (9 transitions)
    # OTR's masses: 1/H per step, H the longest demo's 10 transitions by default.
    at_h = costs * 9 / 10
    exp = EpisodeLabeller(expert, LabelConfig(squashing="exponential", alpha=5, beta=5))(episode)
    per_demo = 5 * np.exp(-5 * at_h)
    np.testing.assert_allclose(exp, per_demo[np.argmax(per_demo.sum(1))])
    both = EpisodeLabeller(expert, LabelConfig(squashing="linear", alpha=10, top_k=2))(episode)
    np.testing.assert_allclose(both, (-10 * at_h).mean(0))
    own_length = LabelConfig(squashing="linear", alpha=1, top_k=2, episode_length=9)
    np.testing.assert_allclose(EpisodeLabeller(expert, own_length)(episode), -costs.mean(0))
    # The oops squashing against the nearest demo is OOPS's own reward with that demo selection.
    ours = EpisodeLabeller(expert, LabelConfig(squashing="oops"))(episode)
    reference = OOPS(expert, OOPSConfig(demo_selection="nearest"))(episode).rewards
    np.testing.assert_allclose(ours, reference)
    with pytest.raises(ValueError, match="top_k 3 exceeds"):
        EpisodeLabeller(expert, LabelConfig(top_k=3))


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"squashing": "tanh"}, "squashing must be one of 'oops', 'linear', 'exponential'"),
        ({"alpha": 0.0}, "alpha must be positive and finite, got 0.0 (--alpha)"),
        ({"beta": -5.0}, "beta must be positive and finite, got -5.0 (--beta)"),
        ({"alpha": "5"}, "alpha must be a number, got '5' (str) (--alpha)"),
        ({"top_k": 2.5}, "top_k must be an integer, got 2.5 (float) (--top-k)"),
        ({"episode_length": 0}, "episode_length must be >= 1, got 0 (--episode-length)"),
        ({"episode_length": 2**40}, "episode_length must be at most 2,147,483,647"),
    ],
)
def test_a_bad_label_setting_is_a_one_line_error_naming_it_and_its_flag(bad, message):
    with pytest.raises(ValueError) as refused:  # alpha, beta <= 0: the far episodes rewarded most
        LabelConfig(**bad)
    assert message in str(refused.value) and "\n" not in str(refused.value)


def test_label_settings_are_held_as_their_declared_types():
    config = LabelConfig(alpha=np.int64(3), top_k=np.int64(2), episode_length=np.int32(9))
    assert (type(config.alpha), type(config.top_k), type(config.episode_length)) == (
        float,
        int,
        int,
    )


def test_an_episode_is_not_penalised_for_being_short():
    """OTR's per-step mass 1/H: the first 100 steps of an episode that follows a 1000-step demo
    cost a few times what they cost in the full episode (balanced OT spreads them over the whole
    demo), not 10 times more again, as with masses 1/T."""
    t = np.linspace(0, 6, 1001)[:, None]
    demo = np.hstack([np.sin(t), np.cos(t), t / 6])
    episode = demo + np.random.default_rng(0).normal(0, 0.05, demo.shape)
    labeller = EpisodeLabeller([demo], LabelConfig(squashing="linear", alpha=1))
    full_cost = -labeller(episode)[:100].mean()
    short_cost = -labeller(episode[:101]).mean()
    assert 1 < short_cost / full_cost < 5
    per_t = EpisodeLabeller([demo], LabelConfig(squashing="linear", alpha=1, episode_length=100))
    assert -per_t(episode[:101]).mean() == pytest.approx(10 * short_cost)


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


def test_a_minari_file_given_alone_is_copied_alone(tmp_path):
    demo_path, expert = _demos(tmp_path)
    episodes = _episodes(seed=3)
    root = _write_minari(tmp_path / "datasets", _minari_eps(episodes))
    (root / "unrelated.bin").write_bytes(b"x" * 100)  # beside the dataset, not part of it
    (tmp_path / "datasets" / "other.bin").write_bytes(b"y")
    label_dataset(root / "data" / "main_data.hdf5", demo_path, tmp_path / "labelled.hdf5")
    assert (tmp_path / "labelled.hdf5").is_file()
    out = demos.load_any(tmp_path / "labelled.hdf5")
    labeller = EpisodeLabeller(expert)
    for got, want in zip(out.episodes, episodes, strict=True):
        np.testing.assert_allclose(got.rewards, labeller(want.observations))


def test_labelling_checks_the_task_and_the_output_before_it_starts(tmp_path, monkeypatch):
    import ilfo.labelling

    demo_path, _ = _demos(tmp_path)  # Hopper-v5
    walker, hopper_v2 = tmp_path / "walker.npz", tmp_path / "hopper2.npz"
    demos.save(walker, _episodes(seed=1), "Walker2d-v5")
    demos.save(hopper_v2, _episodes(seed=1), "Hopper-v2")
    with pytest.raises(ValueError, match=r"demos of Hopper-v5, .* episodes of Walker2d-v5"):
        label_dataset(walker, demo_path, tmp_path / "w.npz")
    label_dataset(hopper_v2, demo_path, tmp_path / "h.npz")  # another version of the task
    d4rl = _write_d4rl(tmp_path / "data.hdf5", _episodes(seed=2), next_obs=True)
    with pytest.raises(ValueError, match="episodes of Walker2d-v2"):
        label_dataset(d4rl, demo_path, tmp_path / "d.hdf5", env_id="Walker2d-v2")

    def never(*args, **kwargs):
        raise AssertionError("labelled before the output was checked")

    monkeypatch.setattr(ilfo.labelling, "label_episodes", never)
    with pytest.raises(FileNotFoundError, match=r"its folder .*nodir does not exist"):
        label_dataset(hopper_v2, demo_path, tmp_path / "nodir" / "o.npz")
    with pytest.raises(ValueError, match=r"written as a \.npz file"):
        label_dataset(hopper_v2, demo_path, tmp_path / "o.h5")


def test_an_output_that_appears_while_labelling_is_not_overwritten(tmp_path, monkeypatch):
    import ilfo.labelling

    demo_path, _ = _demos(tmp_path)
    data = tmp_path / "data.npz"
    demos.save(data, _episodes(seed=1), "Hopper-v5")
    out = tmp_path / "out.npz"
    write = ilfo.labelling._write_ilfo

    def meanwhile(dataset, partial, data, rewards):
        out.write_bytes(b"someone else's")
        write(dataset, partial, data, rewards)

    monkeypatch.setattr(ilfo.labelling, "_write_ilfo", meanwhile)
    with pytest.raises(FileExistsError, match="appeared while labelling"):
        label_dataset(data, demo_path, out)
    assert out.read_bytes() == b"someone else's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.npz", "demos.npz", "out.npz"]


def test_ant_states_are_compared_without_their_contact_forces(tmp_path):
    from ilfo.envs import CONTACT_FORCE_DIMS, FULL_OBSERVATION_DIMS

    full, forces = FULL_OBSERVATION_DIMS["Ant-v5"], CONTACT_FORCE_DIMS["Ant-v5"]
    rng = np.random.default_rng(0)
    demo = rng.normal(size=(9, full))
    episodes = [rng.normal(size=(8, full)) for _ in range(2)]
    for e in episodes:
        e[:, full - forces :] *= 100.0  # contact forces that would swamp the distance
    demo_path, data = tmp_path / "ant-demo.npz", tmp_path / "ant.npz"
    demos.save(demo_path, [Episode(demo)], "Ant-v5")
    demos.save(data, [Episode(e) for e in episodes], "Ant-v5")
    label_dataset(data, demo_path, tmp_path / "without.npz")
    label_dataset(data, demo_path, tmp_path / "with.npz", contact_forces=True)
    without = demos.load(tmp_path / "without.npz").episodes
    kept = full - forces
    labeller = EpisodeLabeller([demo[:, :kept]])
    for got, e in zip(without, episodes, strict=True):
        assert got.observations.shape[1] == full  # the output keeps every column
        np.testing.assert_allclose(got.rewards, labeller(e[:, :kept]))
    with_forces = demos.load(tmp_path / "with.npz").episodes
    assert not np.allclose(with_forces[0].rewards, without[0].rewards)
    hopper_demo, _ = _demos(tmp_path)
    hopper = tmp_path / "hopper.npz"
    demos.save(hopper, _episodes(seed=1), "Hopper-v5")
    with pytest.raises(ValueError, match="--no-contact-forces applies to Ant-v5"):
        label_dataset(hopper, hopper_demo, tmp_path / "h.npz", contact_forces=False)


def test_cli_and_bad_input(tmp_path, capsys):
    demo_path, _ = _demos(tmp_path)
    data = tmp_path / "data.npz"
    demos.save(data, _episodes(seed=4), "Hopper-v5")
    args = ["label", str(data), "--demos", str(demo_path), "--out", str(tmp_path / "o.npz")]
    assert main([*args, "--squashing", "linear", "--workers", "1", "--oops-reg", "0.1"]) == 0
    captured = capsys.readouterr()
    assert "3 episodes" in captured.out and "labelling" in captured.err  # the progress bar
    # The flags reached the labels: the library's, with the same settings.
    expert = [e.observations for e in demos.load(demo_path).episodes]
    labeller = EpisodeLabeller(expert, LabelConfig(squashing="linear", oops=OOPSConfig(reg=0.1)))
    for got in demos.load(tmp_path / "o.npz").episodes:
        np.testing.assert_allclose(got.rewards, labeller(got.observations.astype(np.float64)))
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


def test_the_labeller_refuses_an_oops_kernel_it_would_ignore():
    with pytest.raises(ValueError, match=r"not by oops\.kernel"):
        LabelConfig(oops=OOPSConfig(kernel="exponential"))
