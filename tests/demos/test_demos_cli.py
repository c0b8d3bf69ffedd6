"""`ilfo demos info` and `ilfo demos convert`."""

import json

import h5py
import numpy as np

from ilfo import demos
from ilfo.cli import main
from ilfo.paths import bundled_demos


def _imitation_npz(path, rng, lengths=(4, 6)):
    obs = [rng.normal(size=(t + 1, 3)) for t in lengths]
    acts = [rng.normal(size=(t, 2)) for t in lengths]
    np.savez(
        path,
        obs=np.concatenate(obs),
        acts=np.concatenate(acts),
        rews=np.ones(sum(lengths)),
        terminal=np.ones(len(lengths), bool),
        indices=np.cumsum(lengths[:-1]),
    )
    return obs


def _minari_dir(root, rng, env_id="Hopper-v5", lengths=(3, 5)):
    data = root / "hopper" / "expert-v0" / "data"
    data.mkdir(parents=True)
    obs = []
    with h5py.File(data / "main_data.hdf5", "w") as f:
        for i, t in enumerate(lengths):
            g = f.create_group(f"episode_{i}")
            obs.append(rng.normal(size=(t + 1, 11)))
            g.create_dataset("observations", data=obs[-1])
            g.create_dataset("actions", data=rng.normal(size=(t, 3)))
            g.create_dataset("rewards", data=np.full(t, 2.0))
            g.create_dataset("terminations", data=np.zeros(t, bool))
            g.create_dataset("truncations", data=np.zeros(t, bool))
    spec = json.dumps({"id": env_id})
    meta = {"dataset_id": "hopper/expert-v0", "env_spec": spec, "data_format": "hdf5"}
    (data / "metadata.json").write_text(json.dumps(meta))
    return data.parent, obs


def test_info_on_bundled_demos(capsys):
    path = str(bundled_demos("Hopper-v5-scripted"))
    assert main(["demos", "info", path, "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["env_id"] == "Hopper-v5" and info["episodes"] == 12
    assert info["lengths"] == [1000] * 12 and info["transitions"] == 12_000
    assert (info["obs_dim"], info["action_dim"]) == (11, 3)
    assert info["return_min"] <= info["return_mean"] <= info["return_max"]
    assert info["return_std"] > 0
    assert info["provenance"]["script"] == "scripts/make_scripted_rollouts.py"
    assert main(["demos", "info", path]) == 0
    text = capsys.readouterr().out
    assert "(ilfo)" in text and "Hopper-v5" in text and "episodes: 12" in text
    assert "mean 1000.0" in text and "return: mean" in text


def test_info_on_foreign_formats(capsys, tmp_path):
    rng = np.random.default_rng(0)
    _imitation_npz(tmp_path / "traj.npz", rng)
    assert main(["demos", "info", str(tmp_path / "traj.npz")]) == 0
    text = capsys.readouterr().out
    assert "(imitation)" in text and "(not recorded)" in text and "episodes: 2" in text
    root, _ = _minari_dir(tmp_path, rng)
    assert main(["demos", "info", str(root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["env_id"] == "Hopper-v5" and info["lengths"] == [3, 5]
    assert info["return_mean"] == 8.0 and info["provenance"]["dataset_id"] == "hopper/expert-v0"
    d4rl = tmp_path / "d4rl.hdf5"  # no next_observations: each episode's last row is dropped
    with h5py.File(d4rl, "w") as f:
        f["observations"] = rng.normal(size=(6, 3))
        f["rewards"] = np.ones(6)
        f["terminals"] = np.array([0, 0, 1, 0, 0, 1], bool)
    assert main(["demos", "info", str(d4rl)]) == 0
    text = capsys.readouterr().out
    assert "return: mean 2.00" in text and "without each episode's last row" in text


def test_convert_round_trips(capsys, tmp_path):
    rng = np.random.default_rng(1)
    obs = _imitation_npz(tmp_path / "traj.npz", rng)
    out = tmp_path / "out.npz"
    args = ["demos", "convert", str(tmp_path / "traj.npz"), str(out)]
    assert main(args) == 2
    assert "pass --env-id" in capsys.readouterr().err
    assert main([*args, "--env-id", "Reacher-v5"]) == 0
    assert "2 episodes of Reacher-v5" in capsys.readouterr().out
    back = demos.load(out)
    assert back.env_id == "Reacher-v5" and back.provenance["source_format"] == "imitation"
    for got, want in zip(back.episodes, obs, strict=True):
        np.testing.assert_array_equal(got.observations, want.astype(np.float32))
    assert main([*args, "--env-id", "Reacher-v5"]) == 2
    assert "--force" in capsys.readouterr().err

    root, obs = _minari_dir(tmp_path / "minari", rng)
    assert main(["demos", "convert", str(root), str(out), "--force"]) == 0
    back = demos.load(out)
    assert back.env_id == "Hopper-v5" and back.provenance["dataset_id"] == "hopper/expert-v0"
    for got, want in zip(back.episodes, obs, strict=True):
        np.testing.assert_array_equal(got.observations, want.astype(np.float32))
        assert got.task_return == 2.0 * (len(want) - 1)

    # ilfo -> ilfo with an env id override: recorded in the provenance.
    again = tmp_path / "again.npz"
    assert main(["demos", "convert", str(out), str(again), "--env-id", "Hopper-v4"]) == 0
    copy = demos.load(again)
    assert copy.env_id == "Hopper-v4"
    assert copy.provenance == {**back.provenance, "env_id_overridden_from": "Hopper-v5"}
    for got, want in zip(copy.episodes, back.episodes, strict=True):
        np.testing.assert_array_equal(got.observations, want.observations)
        np.testing.assert_array_equal(got.actions, want.actions)


def test_bad_inputs_are_clear_errors(capsys, tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04 truncated")
    assert main(["demos", "info", str(junk)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ilfo: error:") and "not a readable .npz archive" in err
    assert main(["demos", "info", str(tmp_path / "missing.npz")]) == 2
    assert "no demonstration file" in capsys.readouterr().err
    src = str(bundled_demos("Hopper-v5-scripted"))
    assert main(["demos", "convert", src, str(tmp_path / "out.hdf5")]) == 2
    assert "must be a .npz file" in capsys.readouterr().err
