import subprocess
import sys

import numpy as np
import pytest

from ilfo.envs import SUPPORTED_ENVS, make_env
from ilfo.envs import bullet as envs_bullet
from ilfo.envs.bullet import BULLET_ENVS, MINITAUR_DUCK_ENV_ID, MINITAUR_ENV_ID


def test_ids_are_registered_and_supported():
    import gymnasium as gym

    for env_id in BULLET_ENVS:
        assert env_id in SUPPORTED_ENVS
        assert gym.spec(env_id).max_episode_steps == 1000


def test_clear_error_without_pybullet(monkeypatch):
    monkeypatch.setitem(sys.modules, "pybullet", None)  # `import pybullet` now fails
    envs_bullet._minitaur_modules.cache_clear()
    try:
        with pytest.raises(ImportError, match=r'pip install -e "\.\[bullet\]"'):
            make_env(MINITAUR_ENV_ID)
    finally:
        envs_bullet._minitaur_modules.cache_clear()


def _random_rollout(env, seed, steps):
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    observations, rewards, flags = [obs], [], []
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 8))
        observations.append(obs)
        rewards.append(reward)
        flags.append(info.get("env_terminated", terminated))
        if terminated or truncated:
            break
    return np.array(observations), np.array(rewards), terminated, truncated, flags


@pytest.mark.parametrize("env_id", BULLET_ENVS)
def test_spaces_and_api(env_id):
    pytest.importorskip("pybullet")
    env = make_env(env_id, fixed_horizon=False)
    try:
        assert env.action_space.shape == (8,) and env.action_space.dtype == np.float32
        np.testing.assert_array_equal(env.action_space.low, -1.0)  # symmetric, one bound
        np.testing.assert_array_equal(env.action_space.high, 1.0)
        assert env.observation_space.shape == (28,)
        assert env.observation_space.dtype == np.float32
        obs, info = env.reset(seed=0)
        assert obs.dtype == np.float32 and obs.shape == (28,) and info == {}
        assert env.observation_space.contains(obs)
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert obs.dtype == np.float32 and obs.shape == (28,)
        assert isinstance(reward, float)
        assert isinstance(terminated, bool) and isinstance(truncated, bool)
        assert isinstance(info, dict)
        assert env.spec.max_episode_steps == 1000
    finally:
        env.close()


@pytest.mark.parametrize("env_id", BULLET_ENVS)
def test_seeding_is_reproducible(env_id):
    pytest.importorskip("pybullet")
    a, b = make_env(env_id), make_env(env_id)
    try:
        first = _random_rollout(a, 7, 20)[0]
        np.testing.assert_array_equal(first, _random_rollout(b, 7, 20)[0])  # another instance
        _random_rollout(a, 8, 5)
        np.testing.assert_array_equal(first, _random_rollout(a, 7, 20)[0])  # same one, reseeded
        other = _random_rollout(b, 8, 20)[0]
        assert not np.array_equal(first[0], other[0])  # the robot is randomised at reset
        assert not np.array_equal(first, other)
    finally:
        a.close()
        b.close()


def test_unseeded_resets_continue_the_stream():
    pytest.importorskip("pybullet")
    env = make_env(MINITAUR_ENV_ID)
    try:
        first, _ = env.reset(seed=3)
        second, _ = env.reset()
        assert not np.array_equal(first, second)
    finally:
        env.close()


def test_duck_standard_mode_terminates():
    pytest.importorskip("pybullet")
    # Random actions shake the duck off its back: at step 152 with seed 2 (a few hundred others).
    env = make_env(MINITAUR_DUCK_ENV_ID, fixed_horizon=False)
    try:
        obs, _, terminated, truncated, _ = _random_rollout(env, 2, 1000)
        assert terminated and not truncated and len(obs) - 1 < 200
    finally:
        env.close()


def test_standard_mode_truncates_at_horizon():
    pytest.importorskip("pybullet")
    env = make_env(MINITAUR_ENV_ID, fixed_horizon=False, horizon=30)
    try:
        obs, _, terminated, truncated, _ = _random_rollout(env, 1, 100)
        assert truncated and not terminated and len(obs) - 1 == 30
    finally:
        env.close()


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.parametrize("env_id", BULLET_ENVS)
def test_fixed_horizon_runs_1000_steps_ignoring_termination(env_id):
    pytest.importorskip("pybullet")
    env = make_env(env_id, fixed_horizon=True)
    try:
        obs, rewards, terminated, truncated, flags = _random_rollout(env, 1, 2000)
        assert len(rewards) == 1000 and truncated and not terminated
        assert any(flags)  # a fall (or the duck's) was recorded, and the episode went on
        assert np.isfinite(obs).all() and np.isfinite(rewards).all()
    finally:
        env.close()


def test_fixed_horizon_ignores_termination_short():
    pytest.importorskip("pybullet")
    # Seed 2's random actions end a standard duck episode before step 200 (see above).
    env = make_env(MINITAUR_DUCK_ENV_ID, fixed_horizon=True, horizon=250)
    try:
        obs, _, terminated, truncated, flags = _random_rollout(env, 2, 1000)
        assert len(obs) - 1 == 250 and truncated and not terminated and any(flags)
    finally:
        env.close()


@pytest.mark.integration
def test_import_leaves_no_gym_behind():
    pytest.importorskip("pybullet")
    code = (
        "import sys\n"
        "path = list(sys.path)\n"
        "from ilfo.envs import make_env\n"
        "env = make_env('MinitaurBulletEnv-v0', seed=0)\n"
        "env.step(env.action_space.sample())\n"
        "env.close()\n"
        "names = [m for m in sys.modules if m.split('.')[0] in"
        " ('gym', 'pkg_resources', 'pybullet_envs')]\n"
        "assert not names, names\n"
        "assert sys.path == path\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout == "ok\n"  # and nothing else printed: no "urdf_root=", no "argv[0]="
